#pragma once
// METHOD 3.3: DPaRF, the deformable partial radiance fields. Each token owns a local frame
// (origin Oc = cluster mean of the posed vertices in the SMPL frame, axes Rc = cluster mean of
// the blended rotations, not re-orthonormalised [parity]); a query point reads its Nk nearest
// fields, weighted by softmax(-distance / T), each with its local coordinates encoded.

#include <torch/types.h>

#include "core/config.hpp"

namespace th::model {

struct TokenFrames {
  torch::Tensor origins;    // (Nt, 3) Oc, SMPL frame
  torch::Tensor rotations;  // (Nt, 3, 3) Rc
};

// xs_vertices: (Nv, 3) posed vertices in the SMPL frame; A: (Nv, 3, 3); labels: (Nv) int64.
TokenFrames token_frames(const torch::Tensor& xs_vertices, const torch::Tensor& A,
                         const torch::Tensor& labels, int64_t num_tokens);

// The Nk nearest fields of N points.
struct FieldQuery {
  torch::Tensor index;   // (N, Nk) int64 token ids, nearest first
  torch::Tensor weight;  // (N, Nk) w_k = softmax_k(-d_k / T)
  torch::Tensor coords;  // (N, G): sum_k w_k g_k (relative), PE(xs) (absolute); undefined (none)
};

class DPaRF {
 public:
  // The coordinate encoding's form (relative, absolute or none) is chosen here, once.
  explicit DPaRF(const DPaRFConfig& config);

  // Width G of the coordinate encoding: 63 for relative/absolute (10 frequencies), 0 for none.
  int64_t coord_dim() const {
    return config_.coordinate == Coordinate::none ? 0 : 3 + 6 * config_.pe_freqs;
  }

  // xs: (N, 3) points in the SMPL frame. The nearest fields, their weights and the local
  // coordinates' encoding arguments in one pass per point (model/kernels/nearest_fields.hpp),
  // then the coordinate encoding.
  FieldQuery query(const TokenFrames& frames, const torch::Tensor& xs) const;

 private:
  DPaRFConfig config_;
  bool fused_;  // pe_rounding: fused [parity] (METHOD 3.3)
};

}  // namespace th::model
