#include "model/kernels/view_attention.hpp"

#include <ATen/Parallel.h>
#include <torch/torch.h>

#include <cmath>
#include <limits>
#include <vector>

#include "model/kernels/forms.hpp"

namespace th::model::kernels {
namespace {

// One call's operands, row-major: qr = [q | r] and kv = [k | u], (N, V, W) with W = d + C.
template <class T>
struct Operands {
  const T* qr;
  const T* kv;
  int64_t V, d, C;
  T scale;  // 1 / sqrt(d)
  int64_t width() const { return d + C; }
};

// What the backward pass reads and writes: the saved attention weights (N, V, V), the output
// gradient (N, V, C), the gradients of qr and kv (N, V, W), and V * V scratch.
template <class T>
struct Gradients {
  const T* att;
  const T* grad_out;
  T* grad_qr;
  T* grad_kv;
  T* scratch;
};

// Sixteen independent partial sums, so that the compiler vectorises the reduction (a plain
// running sum is a dependency chain it must keep in order).
template <class T>
inline __attribute__((always_inline)) T dot(const T* __restrict a, const T* __restrict b,
                                            int64_t c) {
  T acc[16] = {};
  int64_t i = 0;
  for (; i + 16 <= c; i += 16)
    for (int j = 0; j < 16; ++j) acc[j] += a[i + j] * b[i + j];
  T s = 0;
  for (; i < c; ++i) s += a[i] * b[i];
  for (int j = 0; j < 16; ++j) s += acc[j];
  return s;
}

template <class T>
inline __attribute__((always_inline)) void axpy(T* __restrict y, T a, const T* __restrict x,
                                                int64_t c) {
  for (int64_t i = 0; i < c; ++i) y[i] += a * x[i];
}

// Forward of points [b, e): out (N, V, C) holds r on entry and the output on return; att
// (N, V, V) receives the attention weights.
template <class T>
inline __attribute__((always_inline)) void attend_rows(Operands<T> x, T* out, T* att, int64_t b,
                                                       int64_t e) {
  const int64_t V = x.V, d = x.d, C = x.C, W = x.width();
  for (int64_t n = b; n < e; ++n) {
    T* a = att + n * V * V;
    for (int64_t v = 0; v < V; ++v) {
      const T* q = x.qr + (n * V + v) * W;
      T m = -std::numeric_limits<T>::infinity(), s = 0;
      for (int64_t j = 0; j < V; ++j)
        m = std::max(m, a[v * V + j] = dot(q, x.kv + (n * V + j) * W, d) * x.scale);
      for (int64_t j = 0; j < V; ++j) s += (a[v * V + j] = std::exp(a[v * V + j] - m));
      for (int64_t j = 0; j < V; ++j)
        axpy(out + (n * V + v) * C, a[v * V + j] /= s, x.kv + (n * V + j) * W + d, C);
    }
  }
}

// Backward of points [b, e).
template <class T>
inline __attribute__((always_inline)) void attend_rows_backward(Operands<T> x, Gradients<T> g,
                                                                int64_t b, int64_t e) {
  const int64_t V = x.V, d = x.d, C = x.C, W = x.width();
  T* ga = g.scratch;
  for (int64_t n = b; n < e; ++n) {
    const T* a = g.att + n * V * V;
    for (int64_t v = 0; v < V; ++v) {
      const T* gv = g.grad_out + (n * V + v) * C;
      T inner = 0;
      for (int64_t j = 0; j < V; ++j) {
        axpy(g.grad_kv + (n * V + j) * W + d, a[v * V + j], gv, C);  // d u_j
        ga[v * V + j] = dot(gv, x.kv + (n * V + j) * W + d, C);
        inner += a[v * V + j] * ga[v * V + j];
      }
      for (int64_t j = 0; j < V; ++j) {
        const T gl = a[v * V + j] * (ga[v * V + j] - inner) * x.scale;
        axpy(g.grad_qr + (n * V + v) * W, gl, x.kv + (n * V + j) * W, d);  // d q_v
        axpy(g.grad_kv + (n * V + j) * W, gl, x.qr + (n * V + v) * W, d);  // d k_j
      }
    }
  }
}

// float: one clone per vector width, chosen at run time (the project builds for baseline x86-64).
__attribute__((target_clones("avx512f", "avx2", "default"))) void attend_rows_f(
    Operands<float> x, float* out, float* att, int64_t b, int64_t e) {
  attend_rows<float>(x, out, att, b, e);
}
__attribute__((target_clones("avx512f", "avx2", "default"))) void attend_rows_backward_f(
    Operands<float> x, Gradients<float> g, int64_t b, int64_t e) {
  attend_rows_backward<float>(x, g, b, e);
}
void attend_rows_any(Operands<float> x, float* out, float* att, int64_t b, int64_t e) {
  attend_rows_f(x, out, att, b, e);
}
void attend_rows_any(Operands<double> x, double* out, double* att, int64_t b, int64_t e) {
  attend_rows<double>(x, out, att, b, e);
}
void attend_rows_backward_any(Operands<float> x, Gradients<float> g, int64_t b, int64_t e) {
  attend_rows_backward_f(x, g, b, e);
}
void attend_rows_backward_any(Operands<double> x, Gradients<double> g, int64_t b, int64_t e) {
  attend_rows_backward<double>(x, g, b, e);
}

template <class T>
Operands<T> operands(const torch::Tensor& qr, const torch::Tensor& kv, int64_t d) {
  const int64_t C = qr.size(2) - d;
  return {qr.data_ptr<T>(),
          kv.data_ptr<T>(),
          qr.size(1),
          d,
          C,
          static_cast<T>(1.0 / std::sqrt(static_cast<double>(d)))};
}

// Packed operands, so that the backward pass writes whole gradients instead of the zero-filled
// slices of narrow().
struct ViewAttention : torch::autograd::Function<ViewAttention> {
  static torch::Tensor forward(torch::autograd::AutogradContext* ctx, const torch::Tensor& qr_in,
                               const torch::Tensor& kv_in, int64_t d) {
    const auto qr = qr_in.contiguous(), kv = kv_in.contiguous();
    const int64_t N = qr.size(0), V = qr.size(1), C = qr.size(2) - d;
    auto out = qr.narrow(2, d, C).contiguous();
    auto att = torch::empty({N, V, V}, qr.options());
    AT_DISPATCH_FLOATING_TYPES(qr.scalar_type(), "view_attention", [&] {
      const auto x = operands<scalar_t>(qr, kv, d);
      scalar_t* o = out.data_ptr<scalar_t>();
      scalar_t* a = att.data_ptr<scalar_t>();
      at::parallel_for(0, N, 64, [&](int64_t b, int64_t e) { attend_rows_any(x, o, a, b, e); });
    });
    ctx->save_for_backward({qr, kv, att});
    ctx->saved_data["d"] = d;
    return out;
  }

  static torch::autograd::variable_list backward(torch::autograd::AutogradContext* ctx,
                                                 torch::autograd::variable_list grads) {
    const auto saved = ctx->get_saved_variables();
    const auto &qr = saved[0], &kv = saved[1], &att = saved[2];
    const int64_t d = ctx->saved_data["d"].toInt();
    const auto g = grads[0].contiguous();
    const int64_t N = qr.size(0), V = qr.size(1), C = qr.size(2) - d;
    auto gqr = torch::empty_like(qr), gkv = torch::zeros_like(kv);
    gqr.narrow(2, 0, d).zero_();
    gqr.narrow(2, d, C).copy_(g);  // r enters the output directly
    AT_DISPATCH_FLOATING_TYPES(qr.scalar_type(), "view_attention_backward", [&] {
      const auto x = operands<scalar_t>(qr, kv, d);
      at::parallel_for(0, N, 64, [&](int64_t b, int64_t e) {
        std::vector<scalar_t> scratch(V * V);
        const Gradients<scalar_t> gr{att.data_ptr<scalar_t>(), g.data_ptr<scalar_t>(),
                                     gqr.data_ptr<scalar_t>(), gkv.data_ptr<scalar_t>(),
                                     scratch.data()};
        attend_rows_backward_any(x, gr, b, e);
      });
    });
    return {gqr, gkv, torch::Tensor()};
  }
};

}  // namespace

torch::Tensor view_attention_weights(const torch::Tensor& q, const torch::Tensor& k) {
  const double scale = 1.0 / std::sqrt(static_cast<double>(q.size(2)));
  return torch::softmax(torch::bmm(q, k.transpose(1, 2)) * scale, 2);
}

torch::Tensor view_attention(const torch::Tensor& qr, const torch::Tensor& kv, int64_t d) {
  TORCH_CHECK(qr.dim() == 3 && qr.sizes() == kv.sizes(),
              "view attention: qr and kv must be (N, V, d + C), got ", qr.sizes(), " and ",
              kv.sizes());
  if (cpu_kernels(qr.device())) return ViewAttention::apply(qr, kv, d);
  const int64_t C = qr.size(2) - d;
  return torch::baddbmm(qr.narrow(2, d, C),
                        view_attention_weights(qr.narrow(2, 0, d), kv.narrow(2, 0, d)),
                        kv.narrow(2, d, C));
}

}  // namespace th::model::kernels
