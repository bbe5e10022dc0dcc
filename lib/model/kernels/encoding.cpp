#include "model/kernels/encoding.hpp"

#include <ATen/Parallel.h>
#include <torch/torch.h>

#include <cmath>

#include "model/kernels/forms.hpp"

namespace th::model::kernels {

torch::Tensor sincos_arguments(const torch::Tensor& x, const torch::Tensor& freqs,
                               const torch::Tensor& phases, bool fused) {
  TORCH_CHECK(x.dim() == 2, "encoding input must be (N, D), got ", x.sizes());
  const int64_t n = x.size(0), dims = x.size(1), nf = freqs.numel();
  const auto f = freqs.view({1, -1, 1}), p = phases.view({1, -1, 1});
  if (!fused) return x.unsqueeze(1) * f + p;
  if (!cpu_kernels(x.device())) {
    // As the plain pass: float64 holds the product of two floats exactly, the sum is rounded
    // there and then to the input's type (the fma's one rounding but for rare double-rounding
    // ties; the same on every device).
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

}  // namespace th::model::kernels
