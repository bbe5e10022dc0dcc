#pragma once
// The heads' means over the reference views (METHOD 3.4) in one pass per point on CPU: the
// density head's mean of e_v, and the colour head's mean of relu(c_v + direction + readout_0) +
// readout_1, read in the type they are stored in (bf16 or fp32) and summed in fp32, the views in
// order, then divided by V, as LibTorch's mean does. On other devices the same in LibTorch
// operations. Differentiable in every input.

#include <torch/types.h>

namespace th::model::kernels {

// x (N, V, C), fp32, float64 or bf16 -> (N, C) in fp32 (float64 for float64).
torch::Tensor view_mean(const torch::Tensor& x);

// base (N, V, C) fp32, float64 or bf16; direction (N, C); readout (N, V, 2 C) or undefined ->
// (N, C) = mean over v of relu(base + direction + readout[..., :C]) + readout[..., C:], or of
// relu(base + direction) without a readout, in fp32 (float64 for float64).
torch::Tensor colour_mean(const torch::Tensor& base, const torch::Tensor& direction,
                          const torch::Tensor& readout);

}  // namespace th::model::kernels
