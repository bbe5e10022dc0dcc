#include "model/human.hpp"

#include "core/error.hpp"
#include "model/sampling.hpp"
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

torch::Tensor TokenFieldsImpl::forward(const HumanStage& stage, const torch::Tensor& xs,
                                       const Products&) {
  const auto& st = std::get<TokenStage>(stage);
  const auto h = dparf.features(st.frames, st.tokens, xs);  // (N, V, C + G)
  return torch::relu(fc_0(h));
}

HumanStage TokenTableImpl::prepare(const FrameInputs& in, const PaintedBody& body) {
  auto t = tokens(in, body);
  return TokenTableStage{t.frames, token_table(t.features, fc_0), {}};  // METHOD 9 (shortcuts.hpp)
}

torch::Tensor TokenTableImpl::forward(const HumanStage& stage, const torch::Tensor& xs,
                                      const Products& products) {
  const auto& st = std::get<TokenTableStage>(stage);
  // The token table's rows of the Nk nearest fields, then fc_0's coordinate part.
  const auto q = dparf.query(st.frames, xs);
  const auto n = xs.size(0);
  auto s = weighted_gather(st.table, {q.index, q.weight}, st.table_grad_sink).view({n, -1, 256});
  if (q.coords.defined()) {
    const auto C = fc_0->weight.size(1) - q.coords.size(1);
    s.add_(
        products.linear_fp32(q.coords, fc_0->weight.narrow(1, C, q.coords.size(1))).unsqueeze(1));
  }
  return s.relu_();
}

std::shared_ptr<HumanRepresentation> make_human_representation(const ModelConfig& config) {
  if (config.representation == Representation::spc_trilinear)
    return std::make_shared<SPCTrilinearImpl>(config);
  if (config.exact_shortcuts) return std::make_shared<TokenTableImpl>(config);
  return std::make_shared<TokenFieldsImpl>(config);
}

}  // namespace th::model
