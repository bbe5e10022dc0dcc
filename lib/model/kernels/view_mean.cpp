#include "model/kernels/view_mean.hpp"

#include <ATen/Parallel.h>
#include <torch/torch.h>

#include <vector>

#include "model/kernels/bf16.hpp"
#include "model/kernels/forms.hpp"
#include "model/kernels/work.hpp"

namespace th::model::kernels {
namespace {

template <class T>
inline __attribute__((always_inline)) T load(const T* x, int64_t i) {
  return x[i];
}
inline __attribute__((always_inline)) float load(const c10::BFloat16* x, int64_t i) {
  return bf16_value(reinterpret_cast<const uint16_t*>(x)[i]);
}

// One point: out[c] = (sum over v of the term) / V, the views summed in order from zero.
// Without `direction`, the term is x[v, c] (view_mean); with it, relu(x[v, c] + direction[c] +
// readout[v, c]) + readout[v, C + c], or relu(x[v, c] + direction[c]) without a readout.
template <class T, class S>
inline __attribute__((always_inline)) void mean_row(const S* __restrict x,
                                                    const T* __restrict direction,
                                                    const T* __restrict readout, int64_t V,
                                                    int64_t C, T* __restrict out) {
  for (int64_t c = 0; c < C; ++c) out[c] = 0;
  for (int64_t v = 0; v < V; ++v) {
    const S* xv = x + v * C;
    if (!direction) {
      for (int64_t c = 0; c < C; ++c) out[c] += load(xv, c);
    } else if (!readout) {
      for (int64_t c = 0; c < C; ++c) {
        const T t = load(xv, c) + direction[c];
        out[c] += t < T(0) ? T(0) : t;
      }
    } else {
      const T* r = readout + v * 2 * C;
      for (int64_t c = 0; c < C; ++c) {
        T t = (load(xv, c) + direction[c]) + r[c];
        t = t < T(0) ? T(0) : t;  // NaN stays NaN
        out[c] += t + r[C + c];
      }
    }
  }
  for (int64_t c = 0; c < C; ++c) out[c] /= T(V);
}

__attribute__((target_clones("avx512f", "avx2", "default"))) void mean_row_f(
    const float* x, const float* d, const float* r, int64_t V, int64_t C, float* out) {
  mean_row<float, float>(x, d, r, V, C, out);
}
__attribute__((target_clones("avx512f", "avx2", "default"))) void mean_row_b(
    const c10::BFloat16* x, const float* d, const float* r, int64_t V, int64_t C, float* out) {
  mean_row<float, c10::BFloat16>(x, d, r, V, C, out);
}

// x (N, V, C) contiguous; direction (N, C) and readout (N, V, 2 C) contiguous or undefined.
torch::Tensor mean_cpu(const torch::Tensor& x, const torch::Tensor& direction,
                       const torch::Tensor& readout) {
  const int64_t N = x.size(0), V = x.size(1), C = x.size(2);
  const auto type = x.scalar_type() == torch::kBFloat16 ? torch::kFloat : x.scalar_type();
  auto out = torch::empty({N, C}, x.options().dtype(type));
  if (type == torch::kDouble) {
    const double* px = x.data_ptr<double>();
    const double* d = direction.defined() ? direction.data_ptr<double>() : nullptr;
    const double* r = readout.defined() ? readout.data_ptr<double>() : nullptr;
    double* o = out.data_ptr<double>();
    at::parallel_for(0, N, 256, [&](int64_t b, int64_t e) {
      for (int64_t n = b; n < e; ++n)
        mean_row<double, double>(px + n * V * C, d ? d + n * C : nullptr,
                                 r ? r + n * V * 2 * C : nullptr, V, C, o + n * C);
    });
    return out;
  }
  const float* d = direction.defined() ? direction.data_ptr<float>() : nullptr;
  const float* r = readout.defined() ? readout.data_ptr<float>() : nullptr;
  float* o = out.data_ptr<float>();
  const bool bf16 = x.scalar_type() == torch::kBFloat16;
  const float* pf = bf16 ? nullptr : x.data_ptr<float>();
  const c10::BFloat16* pb = bf16 ? x.data_ptr<c10::BFloat16>() : nullptr;
  at::parallel_for(0, N, 256, [&](int64_t b, int64_t e) {
    for (int64_t n = b; n < e; ++n) {
      const float* dn = d ? d + n * C : nullptr;
      const float* rn = r ? r + n * V * 2 * C : nullptr;
      if (bf16)
        mean_row_b(pb + n * V * C, dn, rn, V, C, o + n * C);
      else
        mean_row_f(pf + n * V * C, dn, rn, V, C, o + n * C);
    }
  });
  return out;
}

// The same in LibTorch operations, in the kernel's order.
torch::Tensor mean_tensors(const torch::Tensor& x, const torch::Tensor& direction,
                           const torch::Tensor& readout) {
  const auto type = x.scalar_type() == torch::kBFloat16 ? torch::kFloat : x.scalar_type();
  auto t = x.to(type);
  if (direction.defined()) {
    t = t + direction.unsqueeze(1);
    if (readout.defined()) {
      const int64_t C = x.size(2);
      t = (t + readout.narrow(2, 0, C)).relu() + readout.narrow(2, C, C);
    } else {
      t = t.relu();
    }
  }
  return t.mean(1);
}

struct ViewMean : torch::autograd::Function<ViewMean> {
  // direction, readout: empty (numel 0) where there is none.
  static torch::Tensor forward(torch::autograd::AutogradContext* ctx, const torch::Tensor& x,
                               const torch::Tensor& direction, const torch::Tensor& readout) {
    ctx->save_for_backward({x, direction, readout});
    const auto d = direction.numel() > 0 ? direction : torch::Tensor();
    const auto r = readout.numel() > 0 ? readout : torch::Tensor();
    return mean_cpu(x, d, r);
  }
  static torch::autograd::variable_list backward(torch::autograd::AutogradContext* ctx,
                                                 torch::autograd::variable_list grads) {
    const auto saved = ctx->get_saved_variables();
    const auto &x = saved[0], &direction = saved[1], &readout = saved[2];
    const int64_t V = x.size(1), C = x.size(2);
    const auto g = grads[0];
    const auto gv = (g / double(V)).unsqueeze(1).expand({g.size(0), V, C});
    if (direction.numel() == 0) return {gv.to(x.scalar_type()), torch::Tensor(), torch::Tensor()};
    auto pre = x.to(g.scalar_type()) + direction.unsqueeze(1);
    if (readout.numel() > 0) pre = pre + readout.narrow(2, 0, C);
    const auto gpre = gv * (pre > 0);
    return {gpre.to(x.scalar_type()), gpre.sum(1),
            readout.numel() > 0 ? torch::cat({gpre, gv}, 2) : torch::Tensor()};
  }
};

torch::Tensor mean_of(const torch::Tensor& x, const torch::Tensor& direction,
                      const torch::Tensor& readout) {
  TORCH_CHECK(x.dim() == 3, "view mean: x must be (N, V, C), got ", x.sizes());
  const int64_t N = x.size(0), V = x.size(1), C = x.size(2);
  if (direction.defined())
    TORCH_CHECK(direction.sizes() == torch::IntArrayRef({N, C}), "colour mean: direction must be (",
                N, ", ", C, "), got ", direction.sizes());
  if (readout.defined())
    TORCH_CHECK(readout.sizes() == torch::IntArrayRef({N, V, 2 * C}),
                "colour mean: readout must be (", N, ", ", V, ", ", 2 * C, "), got ",
                readout.sizes());
  if (!cpu_kernels(x.device())) return mean_tensors(x, direction, readout);
  const auto type = x.scalar_type() == torch::kBFloat16 ? torch::kFloat : x.scalar_type();
  TORCH_CHECK(type == torch::kFloat || type == torch::kDouble,
              "view mean: x must be fp32, float64 or bf16, got ", x.scalar_type());
  // per element and view: an add (four with the colour head's terms); the result read once
  render::count_work(double(N * V * C) * (direction.defined() ? (readout.defined() ? 4 : 3) : 1),
                     bytes_of(x) + bytes_of(direction) + bytes_of(readout) +
                         double(N * C * c10::elementSize(type)));
  const auto empty = torch::empty({0}, x.options().dtype(type));
  return ViewMean::apply(x.contiguous(),
                         direction.defined() ? direction.to(type).contiguous() : empty,
                         readout.defined() ? readout.to(type).contiguous() : empty);
}

}  // namespace

torch::Tensor view_mean(const torch::Tensor& x) { return mean_of(x, {}, {}); }

torch::Tensor colour_mean(const torch::Tensor& base, const torch::Tensor& direction,
                          const torch::Tensor& readout) {
  TORCH_CHECK(direction.defined(), "colour mean: the direction's term is required");
  return mean_of(base, direction, readout);
}

}  // namespace th::model::kernels
