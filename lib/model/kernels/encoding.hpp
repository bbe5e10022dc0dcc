#pragma once
// The arguments x f + phase of the sine-cosine encodings (METHOD 3.2, 3.3), the one part of the
// encoding whose rounding the reference fixes: fused rounds once, as torch.addcmul does with a
// fused multiply-add [parity]. The CPU kernel is an fma loop (the same on every processor), the
// LibTorch form a float64 addcmul rounded to the input's type (model/kernels/forms.hpp).

#include <torch/types.h>

namespace th::model::kernels {

// x: (N, D); freqs, phases: (F) -> (N, F, D), out[n, k, d] = x[n, d] * freqs[k] + phases[k]
// rounded once (fused) or after the product and after the sum (not fused).
torch::Tensor sincos_arguments(const torch::Tensor& x, const torch::Tensor& freqs,
                               const torch::Tensor& phases, bool fused);

}  // namespace th::model::kernels
