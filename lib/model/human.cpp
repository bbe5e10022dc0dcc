#include "model/human.hpp"

#include "core/error.hpp"
#include "model/shortcuts.hpp"
#include "model/spc.hpp"

namespace th::model {

TokenFieldsImpl::TokenFieldsImpl(const ModelConfig& config)
    : dparf(config.dparf), recipe_(token_recipe(config)), nk_(config.dparf.nk) {
  if (config.transhe.enabled) vit = register_module("ViT", TransHE(config.transhe));
  fc_0 = register_module("fc_0", torch::nn::Linear(config.transhe.dim + dparf.coord_dim(), 256));
}

FrameTokens TokenFieldsImpl::tokens(const FrameInputs& in, const PaintedBody& body) {
  auto t = build_tokens(vit ? vit.get() : nullptr, recipe_, in, body);  // null: w/o TransHE
  if (t.features.size(1) < nk_)
    fail("the frame has ", t.features.size(1),
         " non-empty tokens, fewer than model.dparf.nk = ", nk_);
  return t;
}

HumanStage TokenFieldsImpl::prepare(const FrameInputs& in, const PaintedBody& body) {
  auto t = tokens(in, body);
  return TokenStage{t.frames, t.features};
}

torch::Tensor TokenFieldsImpl::forward(const HumanStage& stage, const torch::Tensor& xs) {
  const auto& st = std::get<TokenStage>(stage);
  const auto h = dparf.features(st.frames, st.tokens, xs);  // (N, V, C + G)
  return torch::relu(fc_0(h));
}

HumanStage TokenTableImpl::prepare(const FrameInputs& in, const PaintedBody& body) {
  auto t = tokens(in, body);
  return TokenTableStage{t.frames, token_table(t.features, fc_0), {}};  // METHOD 9 (shortcuts.hpp)
}

std::shared_ptr<HumanRepresentation> make_human_representation(const ModelConfig& config) {
  if (config.representation == Representation::spc_trilinear)
    return std::make_shared<SPCTrilinearImpl>(config);
  if (config.exact_shortcuts) return std::make_shared<TokenTableImpl>(config);
  return std::make_shared<TokenFieldsImpl>(config);
}

}  // namespace th::model
