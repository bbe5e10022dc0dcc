#pragma once
// The view attention of FDI (METHOD 3.4) on packed operands: for each point and query view v,
// r_v + sum_j softmax_j(q_v . k_j / sqrt(d)) u_j, with qr = [q | r] and kv = [k | u] along the
// channels. On CPU a fused per-point kernel with its own backward (batched products of the tiny
// per-point V x V matrices are slow there); on other devices the same formula in LibTorch
// operations.

#include <torch/types.h>

namespace th::model::kernels {

// qr, kv: (N, V, d + C) -> (N, V, C). Differentiable in qr and kv.
torch::Tensor view_attention(const torch::Tensor& qr, const torch::Tensor& kv, int64_t d);

// softmax over the key views j of q_v . k_j / sqrt(d): q, k (N, V, d) -> (N, V, V), indexed
// [n, v (query), j (key)]. LibTorch operations (any device).
torch::Tensor view_attention_weights(const torch::Tensor& q, const torch::Tensor& k);

}  // namespace th::model::kernels
