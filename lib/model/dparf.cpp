#include "model/dparf.hpp"

#include "core/error.hpp"
#include "model/kernels/encoding.hpp"
#include "model/kernels/gather.hpp"
#include "model/kernels/nearest_fields.hpp"
#include "model/spc.hpp"
#include "model/transhe.hpp"
#include "render/volume.hpp"

namespace th::model {

TokenFieldsImpl::TokenFieldsImpl(const ModelConfig& config) : config_(config) {
  if (config.transhe.enabled) vit = register_module("ViT", TransHE(config.transhe));
  fc_0 = register_module("fc_0", torch::nn::Linear(config.transhe.dim + coord_dim(), 256));
}

int64_t TokenFieldsImpl::coord_dim() const {
  const auto& d = config_.dparf;
  return d.coordinate == Coordinate::none ? 0 : 3 + 6 * d.pe_freqs;
}

HumanStage TokenFieldsImpl::prepare(const FrameInputs& in, const PaintedBody& body) {
  const auto& F_v = body.features;
  const auto device = F_v.device();
  const auto labels = in.labels.to(device);
  const int64_t nt = in.num_tokens > 0 ? in.num_tokens : labels.max().item<int64_t>() + 1;
  // Clusters without vertices (possible with grid groupings) have no token.
  const auto keep = cluster_counts(labels, nt).nonzero().flatten();
  // 3.2 tok_v(c): the painted body averaged per token, over every vertex of the cluster,
  // invisible zeros included [parity], or over the visible ones (grouping.mean_over).
  const bool visible = config_.grouping.mean_over == MeanOver::visible;
  auto T_v = cluster_mean(F_v, labels, nt, visible ? in.visibility.to(device) : torch::Tensor())
                 .index_select(1, keep);
  if (vit) {  // w/o TransHE: the means go to DPaRF as they are
    // The token positions P_c: cluster means of the canonical body in float64 [parity], or of
    // the posed body in the SMPL frame (transhe.position), normalised for the encoding.
    const auto& source =
        config_.transhe.position == TokenPosition::observation ? body.xs_vertices : in.canonical;
    const auto P =
        cluster_mean(source.to(device, torch::kDouble), labels, nt).index_select(0, keep);
    T_v = vit->forward(T_v, normalize_token_positions(P, config_.transhe.pe_scale, F_v));
  }
  if (T_v.size(1) < config_.dparf.nk)
    fail("the frame has ", T_v.size(1),
         " non-empty tokens, fewer than model.dparf.nk = ", config_.dparf.nk);
  // 3.3 DPaRF's token frames: Oc and Rc, the cluster means of the posed vertices (SMPL frame)
  // and of the blended rotations.
  const auto& xs = body.xs_vertices;
  const auto A = in.A.to(device, xs.scalar_type()).reshape({-1, 9});
  TokenFrames frames{cluster_mean(xs, labels, nt).index_select(0, keep),
                     cluster_mean(A, labels, nt).index_select(0, keep).view({-1, 3, 3})};
  // The token table (Nt, V * 256): fc_0's token part and bias on each token, view-major.
  const auto C = T_v.size(2);
  const auto table = torch::matmul(T_v, fc_0->weight.narrow(1, 0, C).t()) + fc_0->bias;
  return TokenTableStage{frames, table.permute({1, 0, 2}).reshape({table.size(1), -1}), {}};
}

torch::Tensor TokenFieldsImpl::forward(const HumanStage& human, const torch::Tensor& xs,
                                       const Products& products) {
  TORCH_CHECK(xs.dim() == 2 && xs.size(1) == 3, "DPaRF points must be (N, 3), got ", xs.sizes());
  const auto& stage = std::get<TokenTableStage>(human);
  const auto& dparf = config_.dparf;
  const bool relative = dparf.coordinate == Coordinate::relative;
  const bool fused = dparf.pe_rounding == PeRounding::fused;  // [parity] (METHOD 3.3)
  // The Nk nearest fields k, their weights w_k and (relative) the local coordinates' codes.
  kernels::NearestFields fields;
  {
    render::ScopedTimer timer("dparf.fields");
    fields = kernels::nearest_fields(
        xs, stage.frames.origins, stage.frames.rotations,
        {dparf.nk, dparf.softmax_temperature, relative, dparf.pe_freqs, fused});
  }
  torch::Tensor g;  // sum_k w_k g_k
  {
    render::ScopedTimer timer("dparf.codes");
    if (relative)
      g = kernels::weighted_codes(fields);
    else if (dparf.coordinate == Coordinate::absolute)
      g = kernels::sincos_encoding(xs, dparf.pe_freqs, true, fused);  // PE(xs), for every k
  }
  kernels::GatherEpilogue epilogue{{}, true, products.between(stage.table.scalar_type())};
  if (g.defined()) {  // fc_0's coordinate part, added to every view's row
    render::ScopedTimer timer("dparf.coordinates");
    const auto& w = fc_0->weight;
    epilogue.addend = products.linear_fp32(g, w.narrow(1, w.size(1) - g.size(1), g.size(1)));
  }
  // s_v = relu(table rows + coordinate part), in the type FDI's products read
  render::ScopedTimer timer("dparf.gather");
  return kernels::weighted_gather(stage.table, {fields.index, fields.weight}, stage.table_grad_sink,
                                  epilogue)
      .view({xs.size(0), -1, 256});
}

std::shared_ptr<HumanRepresentation> make_human_representation(const ModelConfig& config) {
  if (config.representation == Representation::spc_trilinear)
    return std::make_shared<SPCTrilinearImpl>(config);
  return std::make_shared<TokenFieldsImpl>(config);
}

}  // namespace th::model
