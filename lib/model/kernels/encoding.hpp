#pragma once
// The sine-cosine encodings of METHOD 3.2 (tokens), 3.3 (local coordinates) and 3.4 (view
// directions). The layout is the reference's: for each frequency, sin of x, y, z, then cos of
// x, y, z; cos is evaluated as sin(x * f + pi/2) in the input's precision [parity]. The arguments
// x f + phase are the one part whose rounding the reference fixes: fused rounds once, as
// torch.addcmul does with a fused multiply-add [parity]. Their CPU kernel is an fma loop (the same
// on every processor), the LibTorch form a float64 addcmul rounded to the input's type.

#include <torch/types.h>

namespace th::model::kernels {

// Frequencies f_k = float(pi) * 2^k and phases {0, float(pi/2)} of the pi-based encodings,
// repeated as in the reference buffers `_freqs` and `_phases`: both (2 * num_freqs).
torch::Tensor pe_frequencies(int64_t num_freqs, const torch::TensorOptions& options);
torch::Tensor pe_phases(int64_t num_freqs, const torch::TensorOptions& options);

// x: (N, D); freqs, phases: (F) -> (N, F, D), out[n, k, d] = x[n, d] * freqs[k] + phases[k]
// rounded once (fused) or after the product and after the sum (not fused).
torch::Tensor sincos_arguments(const torch::Tensor& x, const torch::Tensor& freqs,
                               const torch::Tensor& phases, bool fused);

// x: (N, 3) -> (N, [3 +] 6 * num_freqs): [x,] sin(f0 x), cos(f0 x), sin(f1 x), ...
// Each value is sin(x * f + phase). `fused` (the default of model.transhe/dparf.pe_rounding,
// METHOD 3.2 [parity]) rounds x * f + phase once, as the reference's torch.addcmul does with a
// fused multiply-add; otherwise the product and the sum are rounded separately (numpy).
torch::Tensor sincos_encoding(const torch::Tensor& x, int64_t num_freqs, bool include_input,
                              bool fused = false);

// View-direction encoding gamma(d) (METHOD 3.4, NeRF's embedder, 4 octaves):
// d: (..., 3) unit -> (..., 27) = [d, sin d, cos d, sin 2d, cos 2d, ..., sin 8d, cos 8d].
torch::Tensor direction_encoding(const torch::Tensor& d);
constexpr int64_t kDirectionEncodingDim = 27;

}  // namespace th::model::kernels
