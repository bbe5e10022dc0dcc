#include "model/human.hpp"

#include "core/error.hpp"
#include "model/sampling.hpp"
#include "model/shortcuts.hpp"
#include "model/spc.hpp"

namespace th::model {

TokenFieldsImpl::TokenFieldsImpl(const ModelConfig& config) : dparf(config.dparf), config_(config) {
  if (config.transhe.enabled) vit = register_module("ViT", TransHE(config.transhe));
  fc_0 = register_module("fc_0", torch::nn::Linear(config.transhe.dim + dparf.coord_dim(), 256));
}

void TokenFieldsImpl::prepare(const FrameInputs& in, const PaintedBody& body, HumanStage& stage) {
  const auto t = build_tokens(vit ? vit.get() : nullptr, config_, in, body);  // null: w/o TransHE
  if (t.features.size(1) < config_.dparf.nk)
    fail("the frame has ", t.features.size(1), " non-empty tokens, fewer than model.dparf.nk = ",
         config_.dparf.nk);
  stage.frames = t.frames;
  if (config_.exact_shortcuts) {
    stage.table = token_table(t.features, fc_0);  // METHOD 9 (shortcuts.hpp)
  } else {
    stage.tokens = t.features;
  }
}

torch::Tensor TokenFieldsImpl::forward(const HumanStage& stage, const torch::Tensor& xs, const Products& products) {
  if (!config_.exact_shortcuts) {
    const auto h = dparf.features(stage.frames, stage.tokens, xs);  // (N, V, 255)
    return torch::relu(fc_0(h));
  }
  // The token table's rows of the Nk nearest fields, then fc_0's coordinate part.
  const auto q = dparf.query(stage.frames, xs);
  const auto n = xs.size(0);
  auto s = weighted_gather(stage.table, {q.index, q.weight}, stage.table_grad_sink).view({n, -1, 256});
  if (q.coords.defined()) {
    const auto C = fc_0->weight.size(1) - q.coords.size(1);
    s.add_(products.linear_fp32(q.coords, fc_0->weight.narrow(1, C, q.coords.size(1))).unsqueeze(1));
  }
  return s.relu_();
}

std::shared_ptr<HumanRepresentation> make_human_representation(const ModelConfig& config) {
  if (config.representation == "spc_trilinear") return std::make_shared<SPCTrilinearImpl>(config);
  return std::make_shared<TokenFieldsImpl>(config);
}

}  // namespace th::model
