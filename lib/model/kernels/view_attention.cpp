#include "model/kernels/view_attention.hpp"

#include <ATen/Parallel.h>
#include <torch/torch.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <vector>

#include "model/kernels/bf16.hpp"
#include "model/kernels/forms.hpp"
#include "model/kernels/work.hpp"

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
Operands<T> operands(const T* qr, const T* kv, int64_t V, int64_t d, int64_t C) {
  return {qr, kv, V, d, C, static_cast<T>(1.0 / std::sqrt(static_cast<double>(d)))};
}

template <class T>
void clamp_rows(T* x, int64_t n) {
  for (int64_t i = 0; i < n; ++i) x[i] = x[i] < T(0) ? T(0) : x[i];  // NaN stays NaN
}

// Forward of points [b, e) in the operands' own type: out receives r, then the attention.
template <class T>
void attend_block(const T* qr, const T* kv, int64_t V, int64_t d, int64_t C, bool relu, T* out,
                  T* att, int64_t b, int64_t e) {
  const int64_t W = d + C;
  for (int64_t r = b * V; r < e * V; ++r) std::copy_n(qr + r * W + d, C, out + r * C);
  attend_rows_any(operands(qr, kv, V, d, C), out, att, b, e);
  if (relu) clamp_rows(out + b * V * C, (e - b) * V * C);
}

// The same with bf16 operands and output: each block of points converted to fp32 in scratch,
// attended there, rounded to bf16 once.
void attend_block_bf16(const c10::BFloat16* qr, const c10::BFloat16* kv, int64_t V, int64_t d,
                       int64_t C, bool relu, c10::BFloat16* out, float* att, int64_t b, int64_t e) {
  constexpr int64_t kBlock = 16;  // points per conversion: the scratch stays in L2
  const int64_t W = d + C;
  std::vector<float> q(kBlock * V * W), k(kBlock * V * W), o(kBlock * V * C);
  for (int64_t b0 = b; b0 < e; b0 += kBlock) {
    const int64_t n = std::min(kBlock, e - b0);
    from_bf16(q.data(), qr + b0 * V * W, n * V * W);
    from_bf16(k.data(), kv + b0 * V * W, n * V * W);
    attend_block(q.data(), k.data(), V, d, C, relu, o.data(), att + b0 * V * V, 0, n);
    to_bf16(out + b0 * V * C, o.data(), n * V * C);
  }
}

// Packed operands, so that the backward pass writes whole gradients instead of the zero-filled
// slices of narrow().
struct ViewAttention : torch::autograd::Function<ViewAttention> {
  static torch::Tensor forward(torch::autograd::AutogradContext* ctx, const torch::Tensor& qr_in,
                               const torch::Tensor& kv_in, int64_t d, bool relu) {
    const auto qr = qr_in.contiguous(), kv = kv_in.contiguous();
    const int64_t N = qr.size(0), V = qr.size(1), C = qr.size(2) - d;
    auto out = torch::empty({N, V, C}, qr.options());
    const bool bf16 = qr.scalar_type() == torch::kBFloat16;
    auto att = torch::empty({N, V, V}, qr.options().dtype(bf16 ? torch::kFloat : qr.scalar_type()));
    if (bf16) {
      const auto* q = qr.data_ptr<c10::BFloat16>();
      const auto* k = kv.data_ptr<c10::BFloat16>();
      auto* o = out.data_ptr<c10::BFloat16>();
      float* a = att.data_ptr<float>();
      at::parallel_for(0, N, 64, [&](int64_t b, int64_t e) {
        attend_block_bf16(q, k, V, d, C, relu, o, a, b, e);
      });
    } else {
      AT_DISPATCH_FLOATING_TYPES(qr.scalar_type(), "view_attention", [&] {
        const scalar_t* q = qr.data_ptr<scalar_t>();
        const scalar_t* k = kv.data_ptr<scalar_t>();
        scalar_t* o = out.data_ptr<scalar_t>();
        scalar_t* a = att.data_ptr<scalar_t>();
        at::parallel_for(
            0, N, 64, [&](int64_t b, int64_t e) { attend_block(q, k, V, d, C, relu, o, a, b, e); });
      });
    }
    ctx->save_for_backward({qr, kv, att, relu ? out : torch::Tensor()});
    ctx->saved_data["d"] = d;
    return out;
  }

  // In the attention's type (fp32 for bf16 operands); the gradients in the operands' type.
  static torch::autograd::variable_list backward(torch::autograd::AutogradContext* ctx,
                                                 torch::autograd::variable_list grads) {
    const auto saved = ctx->get_saved_variables();
    const auto& att = saved[2];
    const auto type = saved[0].scalar_type();
    const auto qr = saved[0].to(att.scalar_type()), kv = saved[1].to(att.scalar_type());
    const int64_t d = ctx->saved_data["d"].toInt();
    auto g = grads[0].to(att.scalar_type());
    if (saved[3].defined()) g = g * (saved[3] > 0);  // through the clamp
    g = g.contiguous();
    const int64_t N = qr.size(0), V = qr.size(1), C = qr.size(2) - d;
    auto gqr = torch::empty_like(qr), gkv = torch::zeros_like(kv);
    gqr.narrow(2, 0, d).zero_();
    gqr.narrow(2, d, C).copy_(g);  // r enters the output directly
    AT_DISPATCH_FLOATING_TYPES(qr.scalar_type(), "view_attention_backward", [&] {
      const auto x = operands<scalar_t>(qr.data_ptr<scalar_t>(), kv.data_ptr<scalar_t>(), V, d, C);
      at::parallel_for(0, N, 64, [&](int64_t b, int64_t e) {
        std::vector<scalar_t> scratch(V * V);
        const Gradients<scalar_t> gr{att.data_ptr<scalar_t>(), g.data_ptr<scalar_t>(),
                                     gqr.data_ptr<scalar_t>(), gkv.data_ptr<scalar_t>(),
                                     scratch.data()};
        attend_rows_backward_any(x, gr, b, e);
      });
    });
    return {gqr.to(type), gkv.to(type), torch::Tensor(), torch::Tensor()};
  }
};

}  // namespace

torch::Tensor view_attention_weights(const torch::Tensor& q, const torch::Tensor& k) {
  const double scale = 1.0 / std::sqrt(static_cast<double>(q.size(2)));
  return torch::softmax(torch::bmm(q, k.transpose(1, 2)) * scale, 2);
}

torch::Tensor view_attention(const torch::Tensor& qr, const torch::Tensor& kv, int64_t d,
                             bool relu) {
  TORCH_CHECK(qr.dim() == 3 && qr.sizes() == kv.sizes(),
              "view attention: qr and kv must be (N, V, d + C), got ", qr.sizes(), " and ",
              kv.sizes());
  TORCH_CHECK(qr.scalar_type() == kv.scalar_type(), "view attention: qr is ", qr.scalar_type(),
              ", kv is ", kv.scalar_type());
  if (cpu_kernels(qr.device())) {
    // per point and query view: V dot products of d, V exponentials, V scaled rows of C; r copied
    const double N = double(qr.size(0)), V = double(qr.size(1)), C = double(qr.size(2) - d);
    render::count_work(
        N * V * (V * (2 * double(d) + 2 * C + 4) + (relu ? C : 0)),
        bytes_of(qr) + bytes_of(kv) + N * V * (C * double(qr.element_size()) + V * 4));
    return ViewAttention::apply(qr, kv, d, relu);
  }
  // In fp32 for bf16 operands, as the kernel.
  const auto type = qr.scalar_type();
  const auto work = type == torch::kBFloat16 ? torch::kFloat : type;
  const auto q = qr.to(work), k = kv.to(work);
  const int64_t C = qr.size(2) - d;
  auto out = torch::baddbmm(q.narrow(2, d, C),
                            view_attention_weights(q.narrow(2, 0, d), k.narrow(2, 0, d)),
                            k.narrow(2, d, C));
  return (relu ? out.relu() : out).to(type);
}

}  // namespace th::model::kernels
