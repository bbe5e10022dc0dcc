#include "model/dparf.hpp"

#include <torch/torch.h>

#include <vector>

#include "model/kernels/nearest_fields.hpp"
#include "model/positional_encoding.hpp"
#include "model/transhe.hpp"

namespace th::model {

TokenFrames token_frames(const torch::Tensor& xs_vertices, const torch::Tensor& A,
                         const torch::Tensor& labels, int64_t num_tokens) {
  TORCH_CHECK(xs_vertices.dim() == 2 && xs_vertices.size(1) == 3, "xs_vertices must be (Nv, 3)");
  TORCH_CHECK(A.dim() == 3 && A.size(0) == xs_vertices.size(0), "A must be (Nv, 3, 3)");
  TokenFrames f;
  f.origins = cluster_mean(xs_vertices, labels, num_tokens);
  f.rotations = cluster_mean(A.reshape({-1, 9}), labels, num_tokens).view({num_tokens, 3, 3});
  return f;
}

DPaRF::DPaRF(const DPaRFConfig& config)
    : config_(config), fused_(config.pe_rounding == PeRounding::fused) {}

torch::Tensor DPaRF::coords_from_tensors(const TokenFrames& frames, const torch::Tensor& xs,
                                         const FieldQuery& q) const {
  switch (config_.coordinate) {
    case Coordinate::relative:
      return relative_coords(frames, xs, q);
    case Coordinate::absolute:
      return absolute_coords(frames, xs, q);
    case Coordinate::none:
      break;
  }
  return {};
}

torch::Tensor DPaRF::field_codes(const TokenFrames& frames, const torch::Tensor& xs,
                                 const torch::Tensor& index) const {
  switch (config_.coordinate) {
    case Coordinate::relative:
      return relative_field_codes(frames, xs, index);
    case Coordinate::absolute:
      return absolute_field_codes(frames, xs, index);
    case Coordinate::none:
      break;
  }
  return no_field_codes(frames, xs, index);
}

torch::Tensor DPaRF::local_coordinates(const TokenFrames& frames, const torch::Tensor& xs,
                                       const torch::Tensor& index) {
  const auto n = index.size(0), k = index.size(1);
  const auto flat = index.flatten();
  const auto diff = xs.unsqueeze(1) - frames.origins.index_select(0, flat).view({n, k, 3});
  const auto rot = frames.rotations.index_select(0, flat).view({n, k, 3, 3});
  // l_i = sum_j diff_j Rc[j][i]   (the reference: diff (1x3) @ Rc)
  return (diff.unsqueeze(3) * rot).sum(2);
}

// ---- the coordinate encodings -----------------------------------------------------------------

torch::Tensor DPaRF::no_field_codes(const TokenFrames&, const torch::Tensor& xs,
                                    const torch::Tensor& index) const {
  return torch::empty({index.size(0), index.size(1), 0}, xs.options());
}

torch::Tensor DPaRF::absolute_coords(const TokenFrames&, const torch::Tensor& xs,
                                     const FieldQuery&) const {
  return sincos_encoding(xs, config_.pe_freqs, true, fused_);
}

torch::Tensor DPaRF::absolute_field_codes(const TokenFrames&, const torch::Tensor& xs,
                                          const torch::Tensor& index) const {
  return sincos_encoding(xs, config_.pe_freqs, true, fused_)
      .unsqueeze(1)
      .expand({index.size(0), index.size(1), coord_dim()});
}

torch::Tensor DPaRF::relative_field_codes(const TokenFrames& frames, const torch::Tensor& xs,
                                          const torch::Tensor& index) const {
  const auto l = local_coordinates(frames, xs, index);
  return sincos_encoding(l.reshape({-1, 3}), config_.pe_freqs, true, fused_)
      .view({index.size(0), index.size(1), -1});
}

torch::Tensor DPaRF::relative_coords(const TokenFrames& frames, const torch::Tensor& xs,
                                     const FieldQuery& q) const {
  const auto g = relative_field_codes(frames, xs, q.index);  // (N, Nk, G)
  return torch::bmm(q.weight.unsqueeze(1), g).squeeze(1);
}

FieldQuery DPaRF::query(const TokenFrames& frames, const torch::Tensor& xs) const {
  TORCH_CHECK(xs.dim() == 2 && xs.size(1) == 3, "DPaRF points must be (N, 3), got ", xs.sizes());
  const bool relative = config_.coordinate == Coordinate::relative;
  auto fields = kernels::nearest_fields(
      xs, frames.origins, frames.rotations,
      {config_.nk, config_.softmax_temperature, relative, config_.pe_freqs, fused_});
  FieldQuery q{fields.index, fields.weight, {}};
  switch (config_.coordinate) {
    case Coordinate::relative:
      q.coords = kernels::weighted_codes(fields);  // sum_k w_k g_k
      break;
    case Coordinate::absolute:
      q.coords = sincos_encoding(xs, config_.pe_freqs, true, fused_);  // PE(xs)
      break;
    case Coordinate::none:
      break;
  }
  return q;
}

FieldQuery DPaRF::query_tensors(const TokenFrames& frames, const torch::Tensor& xs) const {
  TORCH_CHECK(xs.dim() == 2 && xs.size(1) == 3, "DPaRF points must be (N, 3), got ", xs.sizes());
  const auto& O = frames.origins;
  const int64_t nk = config_.nk;
  TORCH_CHECK(O.size(0) >= nk, "DPaRF needs at least nk = ", nk, " tokens, the frame has ",
              O.size(0));
  FieldQuery q;
  // Exact squared distances, for the choice only (no graph).
  const auto d2 = (xs.detach().unsqueeze(1) - O.detach().unsqueeze(0)).pow(2).sum(2);
  q.index = std::get<1>(d2.topk(nk, 1, /*largest=*/false, /*sorted=*/true));
  const auto n = xs.size(0);
  const auto diff = xs.unsqueeze(1) - O.index_select(0, q.index.flatten()).view({n, nk, 3});
  const auto dist = diff.norm(2, -1);
  q.weight = torch::softmax(-dist / config_.softmax_temperature, 1);
  q.coords = coords_from_tensors(frames, xs, q);
  return q;
}

torch::Tensor DPaRF::features(const TokenFrames& frames, const torch::Tensor& tokens,
                              const torch::Tensor& xs) const {
  const auto q = query(frames, xs);
  const auto n = xs.size(0), nk = q.index.size(1), V = tokens.size(0);
  std::vector<torch::Tensor> per_view;
  for (int64_t v = 0; v < V; ++v) {
    auto t = tokens[v].index_select(0, q.index.flatten()).view({n, nk, -1});  // (N, Nk, C)
    t = torch::cat({t, field_codes(frames, xs, q.index)}, -1);                // [T_v(k); g_k]
    per_view.push_back((q.weight.unsqueeze(-1) * t).sum(1));
  }
  return torch::stack(per_view, 1);
}

}  // namespace th::model
