#pragma once
// The fp32 product y = x w^T + b through oneDNN's inner-product primitive, with its own backward
// (oneDNN's derivative wants oneDNN-layout gradients): dx = g w through oneDNN, dw = g^T x and
// db = sum g through BLAS. On CPU only; other devices take LibTorch's linear.
//
// Built against oneDNN 2.x's headers (Debian 12's libdnnl-dev) where LibTorch links that same
// shared library, the primitive runs on the tensors' own memory; otherwise the product goes
// through LibTorch's mkldnn_linear, which copies x into a oneDNN tensor and the result out of one.
// The products are the same to the bit; lib/model/CMakeLists.txt decides which path is built.

#include <torch/types.h>

namespace th::model::kernels {

// x2 (M, in) fp32, w (out, in), b (out) or undefined -> (M, out). Differentiable in x2, w and b
// where autograd records. Where onednn_bf16(), x2 and w may be bf16 (b fp32 or bf16): the
// product accumulates in fp32 and y is bf16.
torch::Tensor onednn_linear(const torch::Tensor& x2, const torch::Tensor& w,
                            const torch::Tensor& b);

// Whether onednn_linear takes bf16 operands (only where it calls oneDNN directly).
bool onednn_bf16();

// Whether onednn_linear calls oneDNN directly (built with oneDNN 2's headers, LibTorch linking the
// same library); false: it calls mkldnn_linear.
bool onednn_direct();

}  // namespace th::model::kernels
