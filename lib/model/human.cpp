#include "model/human.hpp"

#include "core/error.hpp"
#include "model/kernels/gather.hpp"
#include "model/shortcuts.hpp"
#include "model/spc.hpp"

namespace th::model {

TokenFieldsImpl::TokenFieldsImpl(const ModelConfig& config)
    : dparf(config.dparf), recipe_(token_recipe(config)), nk_(config.dparf.nk) {
  if (config.transhe.enabled) vit = register_module("ViT", TransHE(config.transhe));
  fc_0 = register_module("fc_0", torch::nn::Linear(config.transhe.dim + dparf.coord_dim(), 256));
}

HumanStage TokenFieldsImpl::prepare(const FrameInputs& in, const PaintedBody& body) {
  auto t = build_tokens(vit ? vit.get() : nullptr, recipe_, in, body);  // null: w/o TransHE
  if (t.features.size(1) < nk_)
    fail("the frame has ", t.features.size(1),
         " non-empty tokens, fewer than model.dparf.nk = ", nk_);
  return TokenTableStage{t.frames, token_table(t.features, fc_0), {}};  // METHOD 9 (shortcuts.hpp)
}

torch::Tensor TokenFieldsImpl::forward(const HumanStage& human, const torch::Tensor& xs,
                                       const Products& products) {
  const auto& stage = std::get<TokenTableStage>(human);
  const auto q = dparf.query(stage.frames, xs);
  auto s = kernels::weighted_gather(stage.table, {q.index, q.weight}, stage.table_grad_sink)
               .view({xs.size(0), -1, 256});
  if (q.coords.defined()) {  // fc_0's coordinate part on sum_k w_k g_k
    const auto& w = fc_0->weight;
    const auto G = q.coords.size(1);
    s.add_(products.linear_fp32(q.coords, w.narrow(1, w.size(1) - G, G)).unsqueeze(1));
  }
  return s.relu_();
}

std::shared_ptr<HumanRepresentation> make_human_representation(const ModelConfig& config) {
  if (config.representation == Representation::spc_trilinear)
    return std::make_shared<SPCTrilinearImpl>(config);
  return std::make_shared<TokenFieldsImpl>(config);
}

}  // namespace th::model
