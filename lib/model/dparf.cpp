#include "model/dparf.hpp"

#include <ATen/Parallel.h>
#include <torch/torch.h>

#include <cmath>
#include <limits>
#include <vector>

#include "model/positional_encoding.hpp"
#include "model/transhe.hpp"

namespace th::model {

TokenFrames token_frames(const torch::Tensor& xs_vertices, const torch::Tensor& A,
                         const torch::Tensor& labels, int64_t num_tokens) {
  TORCH_CHECK(xs_vertices.dim() == 2 && xs_vertices.size(1) == 3, "xs_vertices must be (Nv, 3)");
  TORCH_CHECK(A.dim() == 3 && A.size(0) == xs_vertices.size(0), "A must be (Nv, 3, 3)");
  TokenFrames f;
  f.origins = cluster_mean(xs_vertices, labels, num_tokens);
  f.rotations = cluster_mean(A.reshape({-1, 9}), labels, num_tokens).view({num_tokens, 3, 3});
  return f;
}

DPaRF::DPaRF(const DPaRFConfig& config)
    : config_(config), fused_(config.pe_rounding == PeRounding::fused) {}

torch::Tensor DPaRF::coords_from_pass(const torch::Tensor& xs, const FieldQuery& q,
                                      torch::Tensor& local, torch::Tensor& args) const {
  switch (config_.coordinate) {
    case Coordinate::relative:
      return relative_coords(xs, q, local, args);
    case Coordinate::absolute:
      return absolute_coords(xs, q, local, args);
    case Coordinate::none:
      break;
  }
  return {};
}

torch::Tensor DPaRF::coords_from_tensors(const TokenFrames& frames, const torch::Tensor& xs,
                                         const FieldQuery& q) const {
  switch (config_.coordinate) {
    case Coordinate::relative:
      return relative_coords(frames, xs, q);
    case Coordinate::absolute:
      return absolute_coords(frames, xs, q);
    case Coordinate::none:
      break;
  }
  return {};
}

torch::Tensor DPaRF::field_codes(const TokenFrames& frames, const torch::Tensor& xs,
                                 const torch::Tensor& index) const {
  switch (config_.coordinate) {
    case Coordinate::relative:
      return relative_field_codes(frames, xs, index);
    case Coordinate::absolute:
      return absolute_field_codes(frames, xs, index);
    case Coordinate::none:
      break;
  }
  return no_field_codes(frames, xs, index);
}

torch::Tensor DPaRF::local_coordinates(const TokenFrames& frames, const torch::Tensor& xs,
                                       const torch::Tensor& index) {
  const auto n = index.size(0), k = index.size(1);
  const auto flat = index.flatten();
  const auto diff = xs.unsqueeze(1) - frames.origins.index_select(0, flat).view({n, k, 3});
  const auto rot = frames.rotations.index_select(0, flat).view({n, k, 3, 3});
  // l_i = sum_j diff_j Rc[j][i]   (the reference: diff (1x3) @ Rc)
  return (diff.unsqueeze(3) * rot).sum(2);
}

// ---- the coordinate encodings -----------------------------------------------------------------

torch::Tensor DPaRF::no_field_codes(const TokenFrames&, const torch::Tensor& xs,
                                    const torch::Tensor& index) const {
  return torch::empty({index.size(0), index.size(1), 0}, xs.options());
}

torch::Tensor DPaRF::absolute_coords(const torch::Tensor& xs, const FieldQuery&, torch::Tensor&,
                                     torch::Tensor&) const {
  return sincos_encoding(xs, config_.pe_freqs, true, fused_);
}

torch::Tensor DPaRF::absolute_coords(const TokenFrames&, const torch::Tensor& xs,
                                     const FieldQuery&) const {
  return sincos_encoding(xs, config_.pe_freqs, true, fused_);
}

torch::Tensor DPaRF::absolute_field_codes(const TokenFrames&, const torch::Tensor& xs,
                                          const torch::Tensor& index) const {
  return sincos_encoding(xs, config_.pe_freqs, true, fused_)
      .unsqueeze(1)
      .expand({index.size(0), index.size(1), coord_dim()});
}

torch::Tensor DPaRF::relative_field_codes(const TokenFrames& frames, const torch::Tensor& xs,
                                          const torch::Tensor& index) const {
  const auto l = local_coordinates(frames, xs, index);
  return sincos_encoding(l.reshape({-1, 3}), config_.pe_freqs, true, fused_)
      .view({index.size(0), index.size(1), -1});
}

torch::Tensor DPaRF::relative_coords(const TokenFrames& frames, const torch::Tensor& xs,
                                     const FieldQuery& q) const {
  const auto g = relative_field_codes(frames, xs, q.index);  // (N, Nk, G)
  return torch::bmm(q.weight.unsqueeze(1), g).squeeze(1);
}

torch::Tensor DPaRF::relative_coords(const torch::Tensor& x, const FieldQuery& q,
                                     torch::Tensor& local, torch::Tensor& args) const {
  // g_k = [l_k, sin(args)]; coords = sum_k w_k g_k.
  args.sin_();
  const int64_t n = x.size(0), nk = q.index.size(1), nf2 = 2 * config_.pe_freqs, G = 3 + nf2 * 3;
  auto coords = torch::empty({n, G}, x.options());
  AT_DISPATCH_FLOATING_TYPES(x.scalar_type(), "dparf_coords", [&] {
    const scalar_t* w = q.weight.data_ptr<scalar_t>();
    const scalar_t* l = local.data_ptr<scalar_t>();
    const scalar_t* s = args.data_ptr<scalar_t>();
    scalar_t* c = coords.data_ptr<scalar_t>();
    at::parallel_for(0, n, 256, [&](int64_t begin, int64_t end) {
      for (int64_t i = begin; i < end; ++i) {
        scalar_t* out = c + i * G;
        for (int64_t j = 0; j < G; ++j) out[j] = 0;
        for (int64_t k = 0; k < nk; ++k) {
          const scalar_t wk = w[i * nk + k];
          const scalar_t* lk = l + (i * nk + k) * 3;
          const scalar_t* sk = s + (i * nk + k) * nf2 * 3;
          for (int j = 0; j < 3; ++j) out[j] += wk * lk[j];
          for (int64_t j = 0; j < nf2 * 3; ++j) out[3 + j] += wk * sk[j];
        }
      }
    });
  });
  return coords;
}

namespace {

// Squared distances of one point to all nt origins, given per axis (ox, oy, oz): a loop the
// compiler vectorises, with the same operations per origin as a scalar loop (the float clones
// enable no FMA, so no rounding changes).
template <class T>
inline __attribute__((always_inline)) void squared_distances(T x, T y, T z, const T* __restrict ox,
                                                             const T* __restrict oy,
                                                             const T* __restrict oz, int64_t nt,
                                                             T* __restrict d2) {
  for (int64_t t = 0; t < nt; ++t) {
    const T dx = x - ox[t], dy = y - oy[t], dz = z - oz[t];
    d2[t] = dx * dx + dy * dy + dz * dz;
  }
}
__attribute__((target_clones("avx512f", "avx2", "default"))) void squared_distances_f(
    float x, float y, float z, const float* ox, const float* oy, const float* oz, int64_t nt,
    float* d2) {
  squared_distances<float>(x, y, z, ox, oy, oz, nt, d2);
}
void squared_distances_any(float x, float y, float z, const float* ox, const float* oy,
                           const float* oz, int64_t nt, float* d2) {
  squared_distances_f(x, y, z, ox, oy, oz, nt, d2);
}
void squared_distances_any(double x, double y, double z, const double* ox, const double* oy,
                           const double* oz, int64_t nt, double* d2) {
  squared_distances<double>(x, y, z, ox, oy, oz, nt, d2);
}

// Per point: the nk nearest origins (exact squared distances, nearest first, ties by index),
// softmax(-d / T) weights, local coordinates and the arguments x * f + phase of their encoding.
// origins: (nt, 3); axes: (3, nt), the same origins per axis.
template <class T>
void nearest_fields(const T* xs, const T* origins, const T* axes, const T* rotations, int64_t nt,
                    int64_t nk, double temperature, const T* freqs, const T* phases, int64_t nf2,
                    bool fused, int64_t n_begin, int64_t n_end, int64_t* out_idx, T* out_w,
                    T* out_local, T* out_args) {
  std::vector<T> best_d(nk), dist2(nt);
  std::vector<int64_t> best_i(nk);
  for (int64_t n = n_begin; n < n_end; ++n) {
    const T x = xs[3 * n], y = xs[3 * n + 1], z = xs[3 * n + 2];
    squared_distances_any(x, y, z, axes, axes + nt, axes + 2 * nt, nt, dist2.data());
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
    int64_t* idx = out_idx + n * nk;
    T* w = out_w + n * nk;
    T max_logit = -std::numeric_limits<T>::infinity();
    for (int64_t k = 0; k < nk; ++k) {
      const int64_t t = best_i[k];
      idx[k] = t;
      const T d[3] = {x - origins[3 * t], y - origins[3 * t + 1], z - origins[3 * t + 2]};
      w[k] = -std::sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]) / static_cast<T>(temperature);
      max_logit = std::max(max_logit, w[k]);
      if (out_local) {
        const T* R = rotations + 9 * t;
        T* l = out_local + (n * nk + k) * 3;
        for (int i = 0; i < 3; ++i) l[i] = d[0] * R[i] + d[1] * R[3 + i] + d[2] * R[6 + i];
        T* a = out_args + (n * nk + k) * nf2 * 3;
        for (int64_t f = 0; f < nf2; ++f)
          for (int i = 0; i < 3; ++i) {
            if (fused) {  // rounded once, as the reference's addcmul [parity]
              a[f * 3 + i] = std::fma(l[i], freqs[f], phases[f]);
            } else {
              const T product = l[i] * freqs[f];  // rounded, then the phase added
              a[f * 3 + i] = product + phases[f];
            }
          }
      }
    }
    T sum = 0;
    for (int64_t k = 0; k < nk; ++k) sum += (w[k] = std::exp(w[k] - max_logit));
    for (int64_t k = 0; k < nk; ++k) w[k] /= sum;
  }
}

}  // namespace

FieldQuery DPaRF::query(const TokenFrames& frames, const torch::Tensor& xs) const {
  TORCH_CHECK(xs.dim() == 2 && xs.size(1) == 3, "DPaRF points must be (N, 3), got ", xs.sizes());
  if (!xs.device().is_cpu() || xs.requires_grad()) return query_tensors(frames, xs);
  const int64_t nk = config_.nk, nt = frames.origins.size(0), n = xs.size(0);
  TORCH_CHECK(nt >= nk, "DPaRF needs at least nk = ", nk, " tokens, the frame has ", nt);
  const bool relative = config_.coordinate == Coordinate::relative;
  const int64_t nf2 = 2 * config_.pe_freqs;
  const auto x = xs.contiguous();
  const auto O = frames.origins.to(x.dtype()).contiguous();
  const auto axes = O.t().contiguous();
  const auto R = frames.rotations.to(x.dtype()).reshape({nt, 9}).contiguous();
  const auto freqs = pe_frequencies(config_.pe_freqs, x.options()).contiguous();
  const auto phases = pe_phases(config_.pe_freqs, x.options()).contiguous();
  FieldQuery q;
  q.index = torch::empty({n, nk}, x.options().dtype(torch::kLong));
  q.weight = torch::empty({n, nk}, x.options());
  torch::Tensor local, args;
  if (relative) {
    local = torch::empty({n, nk, 3}, x.options());
    args = torch::empty({n, nk, nf2, 3}, x.options());
  }
  AT_DISPATCH_FLOATING_TYPES(x.scalar_type(), "dparf_query", [&] {
    at::parallel_for(0, n, 256, [&](int64_t begin, int64_t end) {
      nearest_fields<scalar_t>(
          x.data_ptr<scalar_t>(), O.data_ptr<scalar_t>(), axes.data_ptr<scalar_t>(),
          R.data_ptr<scalar_t>(), nt, nk, config_.softmax_temperature, freqs.data_ptr<scalar_t>(),
          phases.data_ptr<scalar_t>(), nf2, fused_, begin, end, q.index.data_ptr<int64_t>(),
          q.weight.data_ptr<scalar_t>(), relative ? local.data_ptr<scalar_t>() : nullptr,
          relative ? args.data_ptr<scalar_t>() : nullptr);
    });
  });
  q.coords = coords_from_pass(x, q, local, args);
  return q;
}

FieldQuery DPaRF::query_tensors(const TokenFrames& frames, const torch::Tensor& xs) const {
  TORCH_CHECK(xs.dim() == 2 && xs.size(1) == 3, "DPaRF points must be (N, 3), got ", xs.sizes());
  const auto& O = frames.origins;
  const int64_t nk = config_.nk;
  TORCH_CHECK(O.size(0) >= nk, "DPaRF needs at least nk = ", nk, " tokens, the frame has ",
              O.size(0));
  FieldQuery q;
  // Candidate selection on |x|^2 - 2 x.O + |O|^2; exact distances of the chosen fields below.
  const auto d2 = torch::addmm((O * O).sum(1).unsqueeze(0), xs, O.t(), 1, -2);
  q.index = std::get<1>(d2.topk(nk, 1, /*largest=*/false, /*sorted=*/true));
  const auto n = xs.size(0);
  const auto diff = xs.unsqueeze(1) - O.index_select(0, q.index.flatten()).view({n, nk, 3});
  const auto dist = diff.norm(2, -1);
  q.weight = torch::softmax(-dist / config_.softmax_temperature, 1);
  q.coords = coords_from_tensors(frames, xs, q);
  return q;
}

torch::Tensor DPaRF::features(const TokenFrames& frames, const torch::Tensor& tokens,
                              const torch::Tensor& xs) const {
  const auto q = query(frames, xs);
  const auto n = xs.size(0), nk = q.index.size(1), V = tokens.size(0);
  std::vector<torch::Tensor> per_view;
  for (int64_t v = 0; v < V; ++v) {
    auto t = tokens[v].index_select(0, q.index.flatten()).view({n, nk, -1});  // (N, Nk, C)
    t = torch::cat({t, field_codes(frames, xs, q.index)}, -1);                // [T_v(k); g_k]
    per_view.push_back((q.weight.unsqueeze(-1) * t).sum(1));
  }
  return torch::stack(per_view, 1);
}

}  // namespace th::model
