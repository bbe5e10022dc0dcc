#include "model/kernels/encoding.hpp"

#include <ATen/Parallel.h>
#include <torch/torch.h>

#include <cmath>
#include <vector>

#include "model/kernels/forms.hpp"

namespace th::model::kernels {

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

torch::Tensor sincos_arguments(const torch::Tensor& x, const torch::Tensor& freqs,
                               const torch::Tensor& phases, bool fused) {
  TORCH_CHECK(x.dim() == 2, "encoding input must be (N, D), got ", x.sizes());
  const int64_t n = x.size(0), dims = x.size(1), nf = freqs.numel();
  const auto f = freqs.view({1, -1, 1}), p = phases.view({1, -1, 1});
  if (!fused) return x.unsqueeze(1) * f + p;
  if (!cpu_kernels(x.device())) {
    // float64 holds the product of two floats exactly, the sum is rounded there and then to the
    // input's type (the fma's one rounding but for rare double-rounding ties; the same on every
    // device).
    const auto d = torch::kDouble;
    return torch::addcmul(p.to(d), x.to(d).unsqueeze(1), f.to(d)).to(x.scalar_type());
  }
  // IEEE fma, whatever the CPU (no gradient: the encoded points carry none in this model)
  auto args = torch::empty({n, nf, dims}, x.options());
  const auto xc = x.contiguous();
  const auto fc = freqs.flatten().contiguous(), pc = phases.flatten().contiguous();
  AT_DISPATCH_FLOATING_TYPES(x.scalar_type(), "sincos_arguments", [&] {
    const scalar_t* xp = xc.data_ptr<scalar_t>();
    const scalar_t* fp = fc.data_ptr<scalar_t>();
    const scalar_t* pp = pc.data_ptr<scalar_t>();
    scalar_t* a = args.data_ptr<scalar_t>();
    at::parallel_for(0, n, 1024, [&](int64_t begin, int64_t end) {
      for (int64_t i = begin; i < end; ++i)
        for (int64_t k = 0; k < nf; ++k)
          for (int64_t d = 0; d < dims; ++d)
            a[(i * nf + k) * dims + d] = std::fma(xp[i * dims + d], fp[k], pp[k]);
    });
  });
  return args;
}

torch::Tensor sincos_encoding(const torch::Tensor& x, int64_t num_freqs, bool include_input,
                              bool fused) {
  TORCH_CHECK(x.dim() == 2, "positional encoding input must be (N, D), got ", x.sizes());
  const auto n = x.size(0);
  const auto embed = torch::sin(sincos_arguments(x, pe_frequencies(num_freqs, x.options()),
                                                 pe_phases(num_freqs, x.options()), fused))
                         .view({n, -1});
  return include_input ? torch::cat({x, embed}, 1) : embed;
}

torch::Tensor direction_encoding(const torch::Tensor& d) {
  TORCH_CHECK(d.size(-1) == 3, "directions must be (..., 3), got ", d.sizes());
  std::vector<torch::Tensor> parts{d};
  for (double f : {1.0, 2.0, 4.0, 8.0}) {
    const auto x = d * f;
    parts.push_back(torch::sin(x));
    parts.push_back(torch::cos(x));
  }
  return torch::cat(parts, -1);
}

}  // namespace th::model::kernels
