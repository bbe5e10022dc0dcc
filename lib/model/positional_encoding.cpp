#include "model/positional_encoding.hpp"

#include <torch/torch.h>

#include <cmath>

#include "model/kernels/encoding.hpp"

namespace th::model {

torch::Tensor pe_frequencies(int64_t num_freqs, const torch::TensorOptions& options) {
  // Reference: pi * 2.0 ** arange(F) in float32, i.e. float(pi) * 2^k exactly.
  const double pi = options.dtype() == torch::kDouble ? M_PI : static_cast<float>(M_PI);
  const auto f = torch::pow(2.0, torch::arange(num_freqs, torch::kDouble)) * pi;
  return f.repeat_interleave(2).to(options);
}

torch::Tensor pe_phases(int64_t num_freqs, const torch::TensorOptions& options) {
  auto p = torch::zeros({2 * num_freqs}, torch::kDouble);
  p.slice(0, 1, 2 * num_freqs, 2).fill_(M_PI / 2);
  return p.to(options);
}

torch::Tensor sincos_encoding(const torch::Tensor& x, int64_t num_freqs, bool include_input,
                              bool fused) {
  TORCH_CHECK(x.dim() == 2, "positional encoding input must be (N, D), got ", x.sizes());
  const auto n = x.size(0);
  const auto embed = torch::sin(kernels::sincos_arguments(x, pe_frequencies(num_freqs, x.options()),
                                                          pe_phases(num_freqs, x.options()), fused))
                         .view({n, -1});
  return include_input ? torch::cat({x, embed}, 1) : embed;
}

torch::Tensor direction_encoding(const torch::Tensor& d) {
  TORCH_CHECK(d.dim() == 2 && d.size(1) == 3, "directions must be (N, 3), got ", d.sizes());
  std::vector<torch::Tensor> parts{d};
  for (double f : {1.0, 2.0, 4.0, 8.0}) {
    const auto x = d * f;
    parts.push_back(torch::sin(x));
    parts.push_back(torch::cos(x));
  }
  return torch::cat(parts, 1);
}

}  // namespace th::model
