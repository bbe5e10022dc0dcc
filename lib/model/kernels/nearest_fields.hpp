#pragma once
// DPaRF's query (METHOD 3.3) in one pass per point on CPU: the Nk nearest token fields, their
// softmax(-distance / T) weights, the local coordinates in each field's frame and the arguments
// of their sine-cosine encoding; then the weighted sum of the fields' coordinate codes. On other
// devices, and for points that require a gradient, the same quantities in LibTorch operations.

#include <torch/types.h>

#include <cstdint>

namespace th::model::kernels {

// What the query computes besides the fields and their weights.
struct FieldQueryOptions {
  int64_t nk = 4;            // fields per point
  double temperature = 1.0;  // of softmax(-d / T)
  bool local = false;        // local coordinates and their encoding arguments (relative codes)
  int64_t pe_freqs = 10;     // frequencies of the local coordinates' encoding
  bool fused = true;         // encoding arguments rounded once (model/kernels/encoding.hpp)
};

struct NearestFields {
  torch::Tensor index;   // (N, Nk) int64 token ids, nearest first (ties by index)
  torch::Tensor weight;  // (N, Nk) w_k = softmax_k(-d_k / T), d_k the exact distance
  torch::Tensor local;   // (N, Nk, 3) l_k = Rc(k)^T (xs - Oc(k)); options.local only
  torch::Tensor args;    // (N, Nk, 2 pe_freqs, 3) l_k f + phase; options.local only
};

// xs: (N, 3) points, origins: (Nt, 3) Oc, rotations: (Nt, 3, 3) Rc, on one device; Nt >= nk.
NearestFields nearest_fields(const torch::Tensor& xs, const torch::Tensor& origins,
                             const torch::Tensor& rotations, const FieldQueryOptions& options);

// The weighted codes sum_k w_k [l_k, sin(args_k)] of a query made with options.local: (N, 3 + 6
// pe_freqs). Takes the sine of fields.args in place.
torch::Tensor weighted_codes(NearestFields& fields);

}  // namespace th::model::kernels
