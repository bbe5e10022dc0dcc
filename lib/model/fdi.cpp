#include "model/fdi.hpp"

#include <ATen/Parallel.h>

#include <cmath>
#include <limits>
#include <vector>

namespace th::model {

namespace F = torch::nn::functional;

namespace {

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

// Forward of points [b, e): QR, KV (N, V, W) rows, W = d + C; O (N, V, C) holds r on entry and
// the output on return; A (N, V, V) receives the attention weights.
template <class T>
inline __attribute__((always_inline)) void attend_rows(const T* QR, const T* KV, T* O, T* A,
                                                       int64_t b, int64_t e, int64_t V, int64_t d,
                                                       int64_t C, T scale) {
  const int64_t W = d + C;
  for (int64_t n = b; n < e; ++n) {
    T* a = A + n * V * V;
    for (int64_t v = 0; v < V; ++v) {
      const T* q = QR + (n * V + v) * W;
      T m = -std::numeric_limits<T>::infinity(), s = 0;
      for (int64_t j = 0; j < V; ++j)
        m = std::max(m, a[v * V + j] = dot(q, KV + (n * V + j) * W, d) * scale);
      for (int64_t j = 0; j < V; ++j) s += (a[v * V + j] = std::exp(a[v * V + j] - m));
      for (int64_t j = 0; j < V; ++j)
        axpy(O + (n * V + v) * C, a[v * V + j] /= s, KV + (n * V + j) * W + d, C);
    }
  }
}

// Backward of points [b, e): G (N, V, C) output gradient; GQR, GKV (N, V, W) receive the
// gradients of the q and k parts (GKV's u part too); ga is V * V scratch.
template <class T>
inline __attribute__((always_inline)) void attend_rows_backward(const T* QR, const T* KV,
                                                                const T* A, const T* G, T* GQR,
                                                                T* GKV, T* ga, int64_t b, int64_t e,
                                                                int64_t V, int64_t d, int64_t C,
                                                                T scale) {
  const int64_t W = d + C;
  for (int64_t n = b; n < e; ++n) {
    const T* a = A + n * V * V;
    for (int64_t v = 0; v < V; ++v) {
      const T* gv = G + (n * V + v) * C;
      T inner = 0;
      for (int64_t j = 0; j < V; ++j) {
        axpy(GKV + (n * V + j) * W + d, a[v * V + j], gv, C);  // d u_j
        ga[v * V + j] = dot(gv, KV + (n * V + j) * W + d, C);
        inner += a[v * V + j] * ga[v * V + j];
      }
      for (int64_t j = 0; j < V; ++j) {
        const T gl = a[v * V + j] * (ga[v * V + j] - inner) * scale;
        axpy(GQR + (n * V + v) * W, gl, KV + (n * V + j) * W, d);  // d q_v
        axpy(GKV + (n * V + j) * W, gl, QR + (n * V + v) * W, d);  // d k_j
      }
    }
  }
}

// float: one clone per vector width, chosen at run time (the project builds for baseline x86-64).
__attribute__((target_clones("avx512f", "avx2", "default"))) void attend_rows_f(
    const float* QR, const float* KV, float* O, float* A, int64_t b, int64_t e, int64_t V,
    int64_t d, int64_t C, float scale) {
  attend_rows<float>(QR, KV, O, A, b, e, V, d, C, scale);
}
__attribute__((target_clones("avx512f", "avx2", "default"))) void attend_rows_backward_f(
    const float* QR, const float* KV, const float* A, const float* G, float* GQR, float* GKV,
    float* ga, int64_t b, int64_t e, int64_t V, int64_t d, int64_t C, float scale) {
  attend_rows_backward<float>(QR, KV, A, G, GQR, GKV, ga, b, e, V, d, C, scale);
}
void attend_rows_any(const float* QR, const float* KV, float* O, float* A, int64_t b, int64_t e,
                     int64_t V, int64_t d, int64_t C, float scale) {
  attend_rows_f(QR, KV, O, A, b, e, V, d, C, scale);
}
void attend_rows_any(const double* QR, const double* KV, double* O, double* A, int64_t b, int64_t e,
                     int64_t V, int64_t d, int64_t C, double scale) {
  attend_rows<double>(QR, KV, O, A, b, e, V, d, C, scale);
}
void attend_rows_backward_any(const float* QR, const float* KV, const float* A, const float* G,
                              float* GQR, float* GKV, float* ga, int64_t b, int64_t e, int64_t V,
                              int64_t d, int64_t C, float scale) {
  attend_rows_backward_f(QR, KV, A, G, GQR, GKV, ga, b, e, V, d, C, scale);
}
void attend_rows_backward_any(const double* QR, const double* KV, const double* A, const double* G,
                              double* GQR, double* GKV, double* ga, int64_t b, int64_t e, int64_t V,
                              int64_t d, int64_t C, double scale) {
  attend_rows_backward<double>(QR, KV, A, G, GQR, GKV, ga, b, e, V, d, C, scale);
}

// Packed operands: qr = [q | r] and kv = [k | u] along the channels, (N, V, d + C), so that the
// backward pass writes whole gradients instead of the zero-filled slices of narrow().
struct ViewAttention : torch::autograd::Function<ViewAttention> {
  static torch::Tensor forward(torch::autograd::AutogradContext* ctx, const torch::Tensor& qr_in,
                               const torch::Tensor& kv_in, int64_t d) {
    const auto qr = qr_in.contiguous(), kv = kv_in.contiguous();
    const int64_t N = qr.size(0), V = qr.size(1), W = qr.size(2), C = W - d;
    const double scale = 1.0 / std::sqrt(static_cast<double>(d));
    auto out = qr.narrow(2, d, C).contiguous();
    auto att = torch::empty({N, V, V}, qr.options());
    AT_DISPATCH_FLOATING_TYPES(qr.scalar_type(), "view_attention", [&] {
      const scalar_t* QR = qr.data_ptr<scalar_t>();
      const scalar_t* KV = kv.data_ptr<scalar_t>();
      scalar_t* O = out.data_ptr<scalar_t>();
      scalar_t* A = att.data_ptr<scalar_t>();
      at::parallel_for(0, N, 64, [&](int64_t b, int64_t e) {
        attend_rows_any(QR, KV, O, A, b, e, V, d, C, static_cast<scalar_t>(scale));
      });
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
    const int64_t N = qr.size(0), V = qr.size(1), W = qr.size(2), C = W - d;
    const double scale = 1.0 / std::sqrt(static_cast<double>(d));
    auto gqr = torch::empty_like(qr), gkv = torch::zeros_like(kv);
    gqr.narrow(2, 0, d).zero_();
    gqr.narrow(2, d, C).copy_(g);  // r enters the output directly
    AT_DISPATCH_FLOATING_TYPES(qr.scalar_type(), "view_attention_backward", [&] {
      const scalar_t* QR = qr.data_ptr<scalar_t>();
      const scalar_t* KV = kv.data_ptr<scalar_t>();
      const scalar_t* G = g.data_ptr<scalar_t>();
      const scalar_t* A = att.data_ptr<scalar_t>();
      scalar_t* GQR = gqr.data_ptr<scalar_t>();
      scalar_t* GKV = gkv.data_ptr<scalar_t>();
      at::parallel_for(0, N, 64, [&](int64_t b, int64_t e) {
        std::vector<scalar_t> ga(V * V);
        attend_rows_backward_any(QR, KV, A, G, GQR, GKV, ga.data(), b, e, V, d, C,
                                 static_cast<scalar_t>(scale));
      });
    });
    return {gqr, gkv, torch::Tensor()};
  }
};

}  // namespace

FDIImpl::FDIImpl(const FDIConfig& config, int64_t pixel_channels) {
  if (config.appearance) {
    alpha_res_0 = register_module("alpha_res_0", torch::nn::Linear(pixel_channels, 256));
    key0 = register_module("key0", torch::nn::Linear(256, 128));
    value0 = register_module("value0", torch::nn::Linear(256, 256));
  }
  if (config.human) {
    key1 = register_module("key1", torch::nn::Linear(256, 128));
    value1 = register_module("value1", torch::nn::Linear(256, 256));
  }
  fc_1 = register_module("fc_1", torch::nn::Linear(256, 256));
  fc_2 = register_module("fc_2", torch::nn::Linear(256, 256));
}

torch::Tensor FDIImpl::attention(const torch::Tensor& q, const torch::Tensor& k) {
  const double scale = 1.0 / std::sqrt(static_cast<double>(q.size(2)));
  return torch::softmax(torch::bmm(q, k.transpose(1, 2)) * scale, 2);
}

torch::Tensor FDIImpl::attend(const torch::Tensor& qr, const torch::Tensor& kv, int64_t d) {
  TORCH_CHECK(qr.dim() == 3 && qr.sizes() == kv.sizes(),
              "attend: qr and kv must be (N, V, d + C), got ", qr.sizes(), " and ", kv.sizes());
  if (!qr.device().is_cpu()) {
    const int64_t C = qr.size(2) - d;
    return torch::baddbmm(qr.narrow(2, d, C), attention(qr.narrow(2, 0, d), kv.narrow(2, 0, d)),
                          kv.narrow(2, d, C));
  }
  return ViewAttention::apply(qr, kv, d);
}

// ---- the reference computation: products in the compute type, scores and softmax in fp32 ----

namespace {
torch::Tensor layer(const torch::nn::Linear& l, const torch::Tensor& x, const Products& P) {
  return P.linear(x, l->weight, l->bias);
}
torch::Tensor layer_fp32(const torch::nn::Linear& l, const torch::Tensor& x, const Products& P) {
  return Products::fp32(layer(l, x, P));
}
}  // namespace

torch::Tensor FDIImpl::forward(const torch::Tensor& s, const torch::Tensor& a, const Products& P) {
  // The paper's cross-attention (both branches), "w/o h" (appearance only), "w/o a" (human only).
  const auto o = key0 && key1 ? cross(s, a, P) : key0 ? self(s, a, P) : human_only(s, a, P);
  return torch::relu(layer(fc_2, torch::relu(layer(fc_1, o, P)), P));
}

torch::Tensor FDIImpl::cross(const torch::Tensor& s, const torch::Tensor& a, const Products& P) {
  const auto att = attention(layer_fp32(key1, s, P), layer_fp32(key0, a, P));
  return layer_fp32(value1, s, P) + torch::bmm(att, layer_fp32(value0, a, P));
}

torch::Tensor FDIImpl::self(const torch::Tensor&, const torch::Tensor& a, const Products& P) {
  const auto k = layer_fp32(key0, a, P);
  const auto o = layer_fp32(value0, a, P);
  return o + torch::bmm(attention(k, k), o);
}

torch::Tensor FDIImpl::human_only(const torch::Tensor& s, const torch::Tensor&, const Products&) {
  return value1(s);
}

// ---- the folded form ---------------------------------------------------------------------------

torch::Tensor FDIImpl::forward_folded(const FDIFolded& f, const torch::Tensor& s,
                                      const torch::Tensor& a, const Products& P) {
  auto pre = key0 && key1 ? cross_folded(f, s, a, P)
             : key0       ? self_folded(f, s, a, P)
                          : human_only_folded(f, s, a, P);
  return P.linear(pre.relu_(), fc_2->weight, fc_2->bias).relu_();
}

torch::Tensor FDIImpl::cross_folded(const FDIFolded& f, const torch::Tensor& s,
                                    const torch::Tensor& a, const Products& P) {
  // (N, V, 128 + 256) each; the attention kernel takes fp32
  const auto kv = Products::fp32(P.linear(a, f.w0, f.b0));
  const auto qr = Products::fp32(P.linear(s, f.w1, f.b1));
  return attend(qr, kv, 128);
}

torch::Tensor FDIImpl::self_folded(const FDIFolded& f, const torch::Tensor&, const torch::Tensor& a,
                                   const Products& P) {
  const auto kv = Products::fp32(P.linear(a, f.w0, f.b0));
  const auto k = kv.narrow(2, 0, 128), u = kv.narrow(2, 128, 256);
  return torch::baddbmm(u + fc_1->bias, attention(k, k), u);
}

torch::Tensor FDIImpl::human_only_folded(const FDIFolded& f, const torch::Tensor& s,
                                         const torch::Tensor&, const Products& P) {
  return P.linear(s, f.w1, f.b1);
}

// fc_1 is linear: folded into both value projections; each key projection shares one product
// with its value projection. fc_1's bias joins the query side where there is one (the attention
// weights multiply the value side).

FDIFolded FDIImpl::fold() const {
  return key0 && key1 ? fold_cross() : key0 ? fold_self() : fold_human_only();
}

FDIFolded FDIImpl::fold_cross() const {
  const auto& W1 = fc_1->weight;
  FDIFolded f;
  f.w0 = torch::cat({key0->weight, torch::mm(W1, value0->weight)}, 0);
  f.b0 = torch::cat({key0->bias, torch::mv(W1, value0->bias)}, 0);
  f.w1 = torch::cat({key1->weight, torch::mm(W1, value1->weight)}, 0);
  f.b1 = torch::cat({key1->bias, torch::mv(W1, value1->bias) + fc_1->bias}, 0);
  return f;
}

FDIFolded FDIImpl::fold_self() const {
  const auto& W1 = fc_1->weight;
  FDIFolded f;
  f.w0 = torch::cat({key0->weight, torch::mm(W1, value0->weight)}, 0);
  f.b0 = torch::cat({key0->bias, torch::mv(W1, value0->bias)}, 0);
  return f;
}

FDIFolded FDIImpl::fold_human_only() const {
  const auto& W1 = fc_1->weight;
  FDIFolded f;
  f.w1 = torch::mm(W1, value1->weight);
  f.b1 = torch::mv(W1, value1->bias) + fc_1->bias;
  return f;
}

}  // namespace th::model
