#pragma once
// The fp32 product y = x w^T + b through oneDNN (a reorder in, the product, a reorder out), with
// its own backward (oneDNN's derivative wants oneDNN-layout gradients): dx = g w through oneDNN,
// dw = g^T x and db = sum g through BLAS. On CPU only; other devices take LibTorch's linear.

#include <torch/types.h>

namespace th::model::kernels {

// x2 (M, in) fp32, w (out, in), b (out) or undefined -> (M, out). Differentiable in x2, w and b
// where autograd records.
torch::Tensor onednn_linear(const torch::Tensor& x2, const torch::Tensor& w,
                            const torch::Tensor& b);

}  // namespace th::model::kernels
