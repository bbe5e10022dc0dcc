#include "model/kernels/nearest_fields.hpp"

#include <ATen/Parallel.h>
#include <torch/torch.h>

#include <cmath>
#include <limits>
#include <vector>

#include "model/kernels/encoding.hpp"
#include "model/kernels/forms.hpp"
#include "model/kernels/work.hpp"

namespace th::model::kernels {
namespace {

// The frame's fields and the query's constants, as the per-point pass reads them.
template <class T>
struct Fields {
  const T* origins;    // (nt, 3)
  const T* axes;       // (3, nt): the same origins per axis
  const T* rotations;  // (nt, 9)
  int64_t nt, nk;
  T temperature;
  const T* freqs;  // (nf2)
  const T* phases;
  int64_t nf2;
  bool fused;
};

// Where the pass writes, per point n: index/weight (nk), local (nk * 3) and args (nk * nf2 * 3),
// the last two null without local coordinates.
template <class T>
struct Outputs {
  int64_t* index;
  T* weight;
  T* local;
  T* args;
};

// Squared distances of one point to all nt origins, given per axis: a loop the compiler
// vectorises, with the same operations per origin as a scalar loop (this file is compiled
// without floating-point contraction, so no clone turns a product and a sum into one FMA).
// The point comes as three values, not an array by reference: its address would escape to the
// out-of-line clones and every store through an output pointer would reload it.
template <class T>
inline __attribute__((always_inline)) void squared_distances(T x, T y, T z,
                                                             const T* __restrict axes, int64_t nt,
                                                             T* __restrict d2) {
  const T* __restrict ox = axes;
  const T* __restrict oy = axes + nt;
  const T* __restrict oz = axes + 2 * nt;
  for (int64_t t = 0; t < nt; ++t) {
    const T dx = x - ox[t], dy = y - oy[t], dz = z - oz[t];
    d2[t] = dx * dx + dy * dy + dz * dz;
  }
}
__attribute__((target_clones("avx512f", "avx2", "default"))) void squared_distances_f(
    float x, float y, float z, const float* axes, int64_t nt, float* d2) {
  squared_distances<float>(x, y, z, axes, nt, d2);
}
void squared_distances_any(float x, float y, float z, const float* axes, int64_t nt, float* d2) {
  squared_distances_f(x, y, z, axes, nt, d2);
}
void squared_distances_any(double x, double y, double z, const double* axes, int64_t nt,
                           double* d2) {
  squared_distances<double>(x, y, z, axes, nt, d2);
}

// The arguments of one field's encoding, a[j * 3 + i] = l[i] * freqs[j] + phases[j], j < nf2:
// rounded once (fma) when fused [parity], else the product rounded and then the phase added.
// A clone per vector width: the avx512f and haswell clones have the FMA instruction, where the
// baseline build would call the C library's fma once per argument.
// (The builtins, not std::fma: its out-of-line wrapper is not inlined into the haswell clone.)
inline __attribute__((always_inline)) float fused_multiply_add(float a, float b, float c) {
  return __builtin_fmaf(a, b, c);
}
inline __attribute__((always_inline)) double fused_multiply_add(double a, double b, double c) {
  return __builtin_fma(a, b, c);
}
template <class T>
inline __attribute__((always_inline)) void field_arguments(T l0, T l1, T l2,
                                                           const T* __restrict freqs,
                                                           const T* __restrict phases, int64_t nf2,
                                                           bool fused, T* __restrict a) {
  if (fused) {
    for (int64_t j = 0; j < nf2; ++j) {
      a[3 * j] = fused_multiply_add(l0, freqs[j], phases[j]);
      a[3 * j + 1] = fused_multiply_add(l1, freqs[j], phases[j]);
      a[3 * j + 2] = fused_multiply_add(l2, freqs[j], phases[j]);
    }
  } else {
    for (int64_t j = 0; j < nf2; ++j) {
      a[3 * j] = l0 * freqs[j] + phases[j];
      a[3 * j + 1] = l1 * freqs[j] + phases[j];
      a[3 * j + 2] = l2 * freqs[j] + phases[j];
    }
  }
}
__attribute__((target_clones("avx512f", "arch=haswell", "default"))) void field_arguments_f(
    float l0, float l1, float l2, const float* freqs, const float* phases, int64_t nf2, bool fused,
    float* a) {
  field_arguments<float>(l0, l1, l2, freqs, phases, nf2, fused, a);
}
void field_arguments_any(float l0, float l1, float l2, const float* freqs, const float* phases,
                         int64_t nf2, bool fused, float* a) {
  field_arguments_f(l0, l1, l2, freqs, phases, nf2, fused, a);
}
void field_arguments_any(double l0, double l1, double l2, const double* freqs, const double* phases,
                         int64_t nf2, bool fused, double* a) {
  field_arguments<double>(l0, l1, l2, freqs, phases, nf2, fused, a);
}

// Points [begin, end): the nk nearest origins (exact squared distances, nearest first, ties by
// index), softmax(-d / T) weights, local coordinates and the arguments x * f + phase of their
// encoding.
template <class T>
void nearest_fields_rows(const T* xs, Fields<T> f, Outputs<T> out, int64_t begin, int64_t end) {
  const int64_t nt = f.nt, nk = f.nk, nf2 = f.nf2;
  std::vector<T> best_d(nk), dist2(nt);
  std::vector<int64_t> best_i(nk);
  for (int64_t n = begin; n < end; ++n) {
    const T x = xs[3 * n], y = xs[3 * n + 1], z = xs[3 * n + 2];
    squared_distances_any(x, y, z, f.axes, nt, dist2.data());
    int64_t count = 0;
    for (int64_t t = 0; t < nt; ++t) {
      const T d2 = dist2[t];
      if (count == nk && !(d2 < best_d[nk - 1])) continue;
      int64_t pos = count < nk ? count++ : nk - 1;
      while (pos > 0 && d2 < best_d[pos - 1]) {
        best_d[pos] = best_d[pos - 1];
        best_i[pos] = best_i[pos - 1];
        --pos;
      }
      best_d[pos] = d2;
      best_i[pos] = t;
    }
    int64_t* idx = out.index + n * nk;
    T* w = out.weight + n * nk;
    T max_logit = -std::numeric_limits<T>::infinity();
    for (int64_t k = 0; k < nk; ++k) {
      const int64_t t = best_i[k];
      idx[k] = t;
      const T* o = f.origins + 3 * t;
      const T d[3] = {x - o[0], y - o[1], z - o[2]};
      w[k] = -std::sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]) / f.temperature;
      max_logit = std::max(max_logit, w[k]);
      if (!out.local) continue;
      const T* R = f.rotations + 9 * t;
      T* l = out.local + (n * nk + k) * 3;
      for (int i = 0; i < 3; ++i) l[i] = d[0] * R[i] + d[1] * R[3 + i] + d[2] * R[6 + i];
      field_arguments_any(l[0], l[1], l[2], f.freqs, f.phases, nf2, f.fused,
                          out.args + (n * nk + k) * nf2 * 3);
    }
    T sum = 0;
    for (int64_t k = 0; k < nk; ++k) sum += (w[k] = std::exp(w[k] - max_logit));
    for (int64_t k = 0; k < nk; ++k) w[k] /= sum;
  }
}

// One point's code: out = sum_k w[k] (local_k, sin args_k), k < nk, in the order k = 0, 1, ...
template <class T>
inline __attribute__((always_inline)) void weighted_code(T* __restrict out, const T* __restrict w,
                                                         const T* __restrict local,
                                                         const T* __restrict sines, int64_t nk,
                                                         int64_t nf2x3) {
  for (int64_t j = 0; j < 3 + nf2x3; ++j) out[j] = 0;
  for (int64_t k = 0; k < nk; ++k) {
    const T wk = w[k];
    const T* __restrict lk = local + k * 3;
    const T* __restrict sk = sines + k * nf2x3;
    for (int j = 0; j < 3; ++j) out[j] += wk * lk[j];
    for (int64_t j = 0; j < nf2x3; ++j) out[3 + j] += wk * sk[j];
  }
}
__attribute__((target_clones("avx512f", "avx2", "default"))) void weighted_code_f(
    float* out, const float* w, const float* local, const float* sines, int64_t nk, int64_t nf2x3) {
  weighted_code<float>(out, w, local, sines, nk, nf2x3);
}
void weighted_code_any(float* out, const float* w, const float* local, const float* sines,
                       int64_t nk, int64_t nf2x3) {
  weighted_code_f(out, w, local, sines, nk, nf2x3);
}
void weighted_code_any(double* out, const double* w, const double* local, const double* sines,
                       int64_t nk, int64_t nf2x3) {
  weighted_code<double>(out, w, local, sines, nk, nf2x3);
}

// The same query in LibTorch operations (other devices, gradients with respect to the points):
// exact squared distances to every origin, as the reference computes them. (Not the expanded
// |x|^2 - 2 x.O + |O|^2: its rounding depends on the product's blocking, so a near tie could pick
// other fields in a training recomputation than in the pass it recomputes.)
NearestFields nearest_fields_tensors(const torch::Tensor& xs, const torch::Tensor& O,
                                     const torch::Tensor& rotations,
                                     const FieldQueryOptions& options) {
  const int64_t n = xs.size(0), nk = options.nk;
  NearestFields q;
  // (N, Nt), for the choice only: no graph
  const auto d2 = (xs.detach().unsqueeze(1) - O.detach().unsqueeze(0)).pow(2).sum(2);
  q.index = std::get<1>(d2.topk(nk, 1, /*largest=*/false, /*sorted=*/true));
  const auto flat = q.index.flatten();
  const auto diff = xs.unsqueeze(1) - O.index_select(0, flat).view({n, nk, 3});
  q.weight = torch::softmax(-diff.norm(2, -1) / options.temperature, 1);
  if (options.local) {
    const auto R = rotations.index_select(0, flat).view({n, nk, 3, 3});
    q.local = (diff.unsqueeze(3) * R).sum(2);  // l_i = sum_j diff_j Rc[j][i]
    q.args =
        sincos_arguments(q.local.reshape({-1, 3}), pe_frequencies(options.pe_freqs, xs.options()),
                         pe_phases(options.pe_freqs, xs.options()), options.fused)
            .view({n, nk, -1, 3});
  }
  return q;
}

}  // namespace

NearestFields nearest_fields(const torch::Tensor& xs, const torch::Tensor& origins,
                             const torch::Tensor& rotations, const FieldQueryOptions& options) {
  TORCH_CHECK(xs.dim() == 2 && xs.size(1) == 3, "DPaRF points must be (N, 3), got ", xs.sizes());
  const int64_t nk = options.nk, nt = origins.size(0), n = xs.size(0);
  TORCH_CHECK(nt >= nk, "DPaRF needs at least nk = ", nk, " tokens, the frame has ", nt);
  if (!cpu_kernels(xs.device()) || xs.requires_grad())
    return nearest_fields_tensors(xs, origins, rotations, options);
  const int64_t nf2 = 2 * options.pe_freqs;
  const auto x = xs.contiguous();
  const auto O = origins.to(x.dtype()).contiguous();
  const auto axes = O.t().contiguous();
  const auto R = rotations.to(x.dtype()).reshape({nt, 9}).contiguous();
  const auto freqs = pe_frequencies(options.pe_freqs, x.options()).contiguous();
  const auto phases = pe_phases(options.pe_freqs, x.options()).contiguous();
  NearestFields q;
  q.index = torch::empty({n, nk}, x.options().dtype(torch::kLong));
  q.weight = torch::empty({n, nk}, x.options());
  if (options.local) {
    q.local = torch::empty({n, nk, 3}, x.options());
    q.args = torch::empty({n, nk, nf2, 3}, x.options());
  }
  {  // per point: 8 operations and a comparison per token; per field its distance, weight,
     // local frame (15) and arguments (one fma each)
    const double local = options.local ? 15 + 2.0 * double(nf2) * 3 : 0;
    render::count_work(double(n) * (9 * double(nt) + double(nk) * (10 + local)),
                       bytes_of(x) + bytes_of(O) + bytes_of(axes) + bytes_of(R) +
                           bytes_of(q.index) + bytes_of(q.weight) + bytes_of(q.local) +
                           bytes_of(q.args));
  }
  AT_DISPATCH_FLOATING_TYPES(x.scalar_type(), "nearest_fields", [&] {
    const Fields<scalar_t> f{O.data_ptr<scalar_t>(),
                             axes.data_ptr<scalar_t>(),
                             R.data_ptr<scalar_t>(),
                             nt,
                             nk,
                             static_cast<scalar_t>(options.temperature),
                             freqs.data_ptr<scalar_t>(),
                             phases.data_ptr<scalar_t>(),
                             nf2,
                             options.fused};
    const Outputs<scalar_t> out{q.index.data_ptr<int64_t>(), q.weight.data_ptr<scalar_t>(),
                                options.local ? q.local.data_ptr<scalar_t>() : nullptr,
                                options.local ? q.args.data_ptr<scalar_t>() : nullptr};
    at::parallel_for(0, n, 256, [&](int64_t begin, int64_t end) {
      nearest_fields_rows<scalar_t>(x.data_ptr<scalar_t>(), f, out, begin, end);
    });
  });
  return q;
}

torch::Tensor weighted_codes(NearestFields& fields) {
  TORCH_CHECK(fields.local.defined() && fields.args.defined(),
              "weighted_codes: the query has no local coordinates");
  const auto& x = fields.local;
  if (!cpu_kernels(x.device()) || x.requires_grad()) {
    const auto g = torch::cat({x, torch::sin(fields.args).flatten(2)}, 2);  // (N, Nk, G)
    return torch::bmm(fields.weight.unsqueeze(1), g).squeeze(1);
  }
  fields.args.sin_();
  count_elementwise(fields.args, 1);
  const int64_t n = x.size(0), nk = x.size(1), nf2x3 = fields.args.size(2) * 3, G = 3 + nf2x3;
  auto codes = torch::empty({n, G}, x.options());
  render::count_work(2.0 * double(n * nk * G), bytes_of(fields.weight) + bytes_of(x) +
                                                   bytes_of(fields.args) + bytes_of(codes));
  AT_DISPATCH_FLOATING_TYPES(x.scalar_type(), "weighted_codes", [&] {
    const scalar_t* w = fields.weight.data_ptr<scalar_t>();
    const scalar_t* l = fields.local.data_ptr<scalar_t>();
    const scalar_t* s = fields.args.data_ptr<scalar_t>();
    scalar_t* c = codes.data_ptr<scalar_t>();
    at::parallel_for(0, n, 256, [&](int64_t begin, int64_t end) {
      for (int64_t i = begin; i < end; ++i)
        weighted_code_any(c + i * G, w + i * nk, l + i * nk * 3, s + i * nk * nf2x3, nk, nf2x3);
    });
  });
  return codes;
}

}  // namespace th::model::kernels
