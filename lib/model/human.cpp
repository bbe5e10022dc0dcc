#include "model/human.hpp"

#include "core/error.hpp"
#include "model/sampling.hpp"
#include "model/spc.hpp"

namespace th::model {

TokenFieldsImpl::TokenFieldsImpl(const ModelConfig& config) : dparf(config.dparf), config_(config) {
  if (config.transhe.enabled) vit = register_module("ViT", TransHE(config.transhe));
  fc_0 = register_module("fc_0", torch::nn::Linear(config.transhe.dim + dparf.coord_dim(), 256));
}

TokenFieldsImpl::Tokens TokenFieldsImpl::tokens(const FrameInputs& in, const torch::Tensor& painted,
                                                const torch::Tensor& xs_vertices) {
  const auto device = painted.device();
  const auto labels = in.labels.to(device);
  const int64_t nt = in.num_tokens > 0 ? in.num_tokens : labels.max().item<int64_t>() + 1;
  Tokens t;
  // Clusters without vertices (possible with grid groupings) have no token.
  t.keep = cluster_counts(labels, nt).nonzero().flatten();
  const auto weights = config_.grouping.mean_over == "visible" ? in.visibility.to(device) : torch::Tensor();
  auto feats = cluster_mean(painted, labels, nt, weights).index_select(1, t.keep);
  // SPEC 3.2: token positions from the canonical body (v_template, float64 means [parity]) or,
  // for the observation-space ablation, from the posed body in the SMPL frame.
  const auto& source = config_.transhe.position == "canonical" ? in.canonical : xs_vertices;
  const auto means = cluster_mean(source.to(device, torch::kDouble), labels, nt).index_select(0, t.keep);
  t.positions = normalize_token_positions(means, config_.transhe.pe_scale, painted);
  t.features = vit ? vit->forward(feats, t.positions) : feats;
  auto frames = token_frames(xs_vertices, in.A.to(device, xs_vertices.scalar_type()), labels, nt);
  t.frames = {frames.origins.index_select(0, t.keep), frames.rotations.index_select(0, t.keep)};
  return t;
}

void TokenFieldsImpl::prepare(const FrameInputs& in, const torch::Tensor& painted,
                              const torch::Tensor& xs_vertices, FrameCache& cache) {
  const auto t = tokens(in, painted, xs_vertices);
  if (t.features.size(1) < config_.dparf.nk)
    fail("the frame has ", t.features.size(1), " non-empty tokens, fewer than model.dparf.nk = ",
         config_.dparf.nk);
  cache.tensors["human.origins"] = t.frames.origins;
  cache.tensors["human.rotations"] = t.frames.rotations;
  if (config_.exact_shortcuts) {
    // SPEC 9: fc_0 is linear and the Nk weights sum to 1, so its token part is applied to the
    // Nt tokens once per frame: table (Nt, V * 256) holds fc_0_T(T_v(c)) + bias for every view.
    const auto C = t.features.size(2);
    const auto w_tok = fc_0->weight.narrow(1, 0, C);
    const auto table = torch::matmul(t.features, w_tok.t()) + fc_0->bias;  // (V, Nt, 256)
    cache.tensors["human.table"] = table.permute({1, 0, 2}).reshape({table.size(1), -1});
  } else {
    cache.tensors["human.tokens"] = t.features;
  }
}

torch::Tensor TokenFieldsImpl::forward(const FrameCache& cache, const torch::Tensor& xs) {
  const TokenFrames frames{cache.at("human.origins"), cache.at("human.rotations")};
  if (!config_.exact_shortcuts) {
    const auto h = dparf.features(frames, cache.at("human.tokens"), xs);  // (N, V, 255)
    return torch::relu(fc_0(h));
  }
  const auto q = dparf.query(frames, xs);
  const auto& table = cache.at("human.table");
  const auto n = xs.size(0);
  auto s = weighted_gather(table, {q.index, q.weight}, cache.sink("human.table")).view({n, -1, 256});
  if (q.coords.defined()) {
    const auto C = fc_0->weight.size(1) - q.coords.size(1);
    s.add_(torch::mm(q.coords, fc_0->weight.narrow(1, C, q.coords.size(1)).t()).unsqueeze(1));
  }
  return s.relu_();
}

std::shared_ptr<HumanRepresentation> make_human_representation(const ModelConfig& config) {
  if (config.representation == "spc_trilinear") return std::make_shared<SPCTrilinearImpl>(config);
  return std::make_shared<TokenFieldsImpl>(config);
}

}  // namespace th::model
