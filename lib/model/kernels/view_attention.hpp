#pragma once
// The view attention of FDI (METHOD 3.4) on packed operands: for each point and query view v,
// r_v + sum_j softmax_j(q_v . k_j / sqrt(d)) u_j, with qr = [q | r] and kv = [k | u] along the
// channels. On CPU a fused per-point kernel with its own backward (batched products of the tiny
// per-point V x V matrices are slow there); on other devices the same formula in LibTorch
// operations.

#include <torch/types.h>

namespace th::model::kernels {

// qr, kv: (N, V, d + C) -> (N, V, C), clamped at zero with `relu`. Differentiable in qr and kv.
// The output has the operands' type: fp32 or float64, or bf16 (bf16 operands are read and the
// output written in bf16; the attention itself runs in fp32, the output rounded once).
torch::Tensor view_attention(const torch::Tensor& qr, const torch::Tensor& kv, int64_t d,
                             bool relu = false);

// softmax over the key views j of q_v . k_j / sqrt(d): q, k (N, V, d) -> (N, V, V), indexed
// [n, v (query), j (key)]. LibTorch operations (any device).
torch::Tensor view_attention_weights(const torch::Tensor& q, const torch::Tensor& k);

}  // namespace th::model::kernels
