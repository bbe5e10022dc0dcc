#include "model/dparf.hpp"

#include <torch/torch.h>

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

}  // namespace th::model
