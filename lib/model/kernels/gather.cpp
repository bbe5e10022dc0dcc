#include "model/kernels/gather.hpp"

#include <ATen/Parallel.h>
#include <torch/torch.h>

#include <algorithm>
#include <cmath>
#include <vector>

#include "model/kernels/bf16.hpp"
#include "model/kernels/forms.hpp"
#include "model/kernels/work.hpp"

namespace th::model::kernels {
namespace {

// The taps of one output row: T (index, weight) pairs into a table of C channels.
template <class T>
struct RowTaps {
  const int64_t* index;
  const T* weight;
  int64_t taps, channels;
};

// Inner loops with a runtime choice of vector width (the project builds for baseline x86-64).
template <class T>
inline __attribute__((always_inline)) void gather_row(T* __restrict out, const T* __restrict table,
                                                      RowTaps<T> r) {
  const int64_t C = r.channels;
  for (int64_t c = 0; c < C; ++c) out[c] = 0;
  for (int64_t t = 0; t < r.taps; ++t) {
    const T w = r.weight[t];
    if (w == T(0)) continue;
    const T* __restrict row = table + r.index[t] * C;
    for (int64_t c = 0; c < C; ++c) out[c] += w * row[c];
  }
}

// The same sum over a bf16 table (per-frame tables stored in bf16, model/precision.hpp): each
// value widened to fp32 as it is read, the sums in fp32.
inline __attribute__((always_inline)) void gather_row_bf16(float* __restrict out,
                                                           const uint16_t* __restrict table,
                                                           RowTaps<float> r) {
  const int64_t C = r.channels;
  for (int64_t c = 0; c < C; ++c) out[c] = 0;
  for (int64_t t = 0; t < r.taps; ++t) {
    const float w = r.weight[t];
    if (w == 0.0f) continue;
    const uint16_t* __restrict row = table + r.index[t] * C;
    for (int64_t c = 0; c < C; ++c) out[c] += w * bf16_value(row[c]);
  }
}

// Adds w * grad_out[c0, c1) into the tapped rows of grad_table.
template <class T>
inline __attribute__((always_inline)) void scatter_row(T* __restrict grad_table,
                                                       const T* __restrict grad_out, RowTaps<T> r,
                                                       int64_t c0, int64_t c1) {
  for (int64_t t = 0; t < r.taps; ++t) {
    const T w = r.weight[t];
    if (w == T(0)) continue;
    T* __restrict row = grad_table + r.index[t] * r.channels;
    for (int64_t c = c0; c < c1; ++c) row[c] += w * grad_out[c];
  }
}

__attribute__((target_clones("avx512f", "avx2", "default"))) void gather_row_f(float* out,
                                                                               const float* table,
                                                                               RowTaps<float> r) {
  gather_row<float>(out, table, r);
}
__attribute__((target_clones("avx512f", "avx2", "default"))) void gather_row_b(
    float* out, const uint16_t* table, RowTaps<float> r) {
  gather_row_bf16(out, table, r);
}
__attribute__((target_clones("avx512f", "avx2", "default"))) void scatter_row_f(
    float* grad_table, const float* grad_out, RowTaps<float> r, int64_t c0, int64_t c1) {
  scatter_row<float>(grad_table, grad_out, r, c0, c1);
}
// The epilogue of a row in place: the addend on each group of G channels, then the clamp.
template <class T>
inline __attribute__((always_inline)) void finish_row(T* __restrict row, const T* __restrict add,
                                                      int64_t C, int64_t G, bool relu) {
  if (add)
    for (int64_t g = 0; g < C; g += G)
      for (int64_t c = 0; c < G; ++c) row[g + c] += add[c];
  if (relu)
    for (int64_t c = 0; c < C; ++c) row[c] = row[c] < T(0) ? T(0) : row[c];  // NaN stays NaN
}
__attribute__((target_clones("avx512f", "avx2", "default"))) void finish_row_f(float* row,
                                                                               const float* add,
                                                                               int64_t C, int64_t G,
                                                                               bool relu) {
  finish_row<float>(row, add, C, G, relu);
}
void finish_row_any(float* row, const float* add, int64_t C, int64_t G, bool relu) {
  finish_row_f(row, add, C, G, relu);
}
void finish_row_any(double* row, const double* add, int64_t C, int64_t G, bool relu) {
  finish_row<double>(row, add, C, G, relu);
}
void gather_row_any(float* out, const float* table, RowTaps<float> r) {
  gather_row_f(out, table, r);
}
void gather_row_any(double* out, const double* table, RowTaps<double> r) {
  gather_row<double>(out, table, r);
}
void gather_row_any(float* out, const c10::BFloat16* table, RowTaps<float> r) {
  gather_row_b(out, reinterpret_cast<const uint16_t*>(table), r);
}
void scatter_row_any(float* gt, const float* g, RowTaps<float> r, int64_t c0, int64_t c1) {
  scatter_row_f(gt, g, r, c0, c1);
}
void scatter_row_any(double* gt, const double* g, RowTaps<double> r, int64_t c0, int64_t c1) {
  scatter_row<double>(gt, g, r, c0, c1);
}

// bf16 rows come from float tables only (weighted_gather checks).
void store_bf16(c10::BFloat16* out, const float* row, int64_t n) { to_bf16(out, row, n); }
void store_bf16(c10::BFloat16*, const double*, int64_t) {}

// The sum type of a table's gather: its own, fp32 for a bf16 table.
c10::ScalarType sum_type(const torch::Tensor& table) {
  return table.scalar_type() == torch::kBFloat16 ? torch::kFloat : table.scalar_type();
}

// Rows of a table of S summed in T (S itself, or fp32 for bf16), finished in cache, written in
// `dtype` (T, or bf16 from fp32 sums).
template <class T, class S>
void gather_rows(const torch::Tensor& table, const torch::Tensor& index,
                 const torch::Tensor& weight, const torch::Tensor& addend, bool relu,
                 torch::Tensor& out) {
  const int64_t M = index.size(0), T_ = index.size(1), C = table.size(1);
  const bool to_bf16_rows = out.scalar_type() != c10::CppTypeToScalarType<T>::value;
  const S* tab = table.data_ptr<S>();
  const int64_t* idx = index.data_ptr<int64_t>();
  const T* w = weight.data_ptr<T>();
  const T* add = addend.defined() ? addend.data_ptr<T>() : nullptr;
  const int64_t G = addend.defined() ? addend.size(1) : C;
  T* o = to_bf16_rows ? nullptr : out.data_ptr<T>();
  c10::BFloat16* ob = to_bf16_rows ? out.data_ptr<c10::BFloat16>() : nullptr;
  at::parallel_for(0, M, 64, [&](int64_t begin, int64_t end) {
    std::vector<T> scratch(to_bf16_rows ? C : 0);
    for (int64_t m = begin; m < end; ++m) {
      T* row = to_bf16_rows ? scratch.data() : o + m * C;
      gather_row_any(row, tab, RowTaps<T>{idx + m * T_, w + m * T_, T_, C});
      if (add || relu) finish_row_any(row, add ? add + m * G : nullptr, C, G, relu);
      if (to_bf16_rows) store_bf16(ob + m * C, row, C);
    }
  });
}

// The forward pass: the output in `dtype` (the sum type, or bf16 from fp32 sums).
torch::Tensor gather_forward_cpu(const torch::Tensor& table, const torch::Tensor& index,
                                 const torch::Tensor& weight, const torch::Tensor& addend,
                                 bool relu, c10::ScalarType dtype) {
  auto out = torch::empty({index.size(0), table.size(1)}, table.options().dtype(dtype));
  if (table.scalar_type() == torch::kBFloat16) {
    gather_rows<float, c10::BFloat16>(table, index, weight, addend, relu, out);
    return out;
  }
  AT_DISPATCH_FLOATING_TYPES(table.scalar_type(), "weighted_gather", [&] {
    gather_rows<scalar_t, scalar_t>(table, index, weight, addend, relu, out);
  });
  return out;
}

// Adds the gradient of the table into grad_table (R, C).
void gather_backward_cpu(const torch::Tensor& grad_out, const torch::Tensor& index,
                         const torch::Tensor& weight, torch::Tensor& grad_table) {
  const int64_t M = index.size(0), T_ = index.size(1), C = grad_out.size(1);
  TORCH_CHECK(grad_table.is_contiguous() && grad_table.size(1) == C,
              "gradient buffer must be contiguous (R, ", C, ")");
  AT_DISPATCH_FLOATING_TYPES(grad_out.scalar_type(), "weighted_gather_backward", [&] {
    const scalar_t* g = grad_out.data_ptr<scalar_t>();
    const int64_t* idx = index.data_ptr<int64_t>();
    const scalar_t* w = weight.data_ptr<scalar_t>();
    scalar_t* gt = grad_table.data_ptr<scalar_t>();
    // Threads split the channels, so no two threads write the same address.
    const int64_t block =
        std::max<int64_t>(16, (C + at::get_num_threads() - 1) / at::get_num_threads());
    const int64_t blocks = (C + block - 1) / block;
    at::parallel_for(0, blocks, 1, [&](int64_t b0, int64_t b1) {
      for (int64_t b = b0; b < b1; ++b) {
        const int64_t c0 = b * block, c1 = std::min(C, c0 + block);
        for (int64_t m = 0; m < M; ++m)
          scatter_row_any(gt, g + m * C, RowTaps<scalar_t>{idx + m * T_, w + m * T_, T_, C}, c0,
                          c1);
      }
    });
  });
}

struct WeightedGather : torch::autograd::Function<WeightedGather> {
  // addend: empty (numel 0) when there is none; dtype: the output's.
  static torch::Tensor forward(torch::autograd::AutogradContext* ctx, const torch::Tensor& table,
                               const torch::Tensor& index, const torch::Tensor& weight,
                               const torch::Tensor& addend,
                               const c10::optional<torch::Tensor>& sink, bool relu, int64_t dtype) {
    const bool add = addend.numel() > 0;
    auto out = gather_forward_cpu(table, index, weight, add ? addend : torch::Tensor(), relu,
                                  static_cast<c10::ScalarType>(dtype));
    ctx->save_for_backward({index, weight, relu ? out : torch::Tensor()});
    ctx->saved_data["rows"] = table.size(0);
    ctx->saved_data["type"] = static_cast<int64_t>(table.scalar_type());
    ctx->saved_data["groups"] = add ? addend.size(1) : int64_t(0);
    // Not a saved variable: other chunks update the sink in place between forward and backward.
    if (sink.has_value()) ctx->saved_data["sink"] = *sink;
    return out;
  }
  static torch::autograd::variable_list backward(torch::autograd::AutogradContext* ctx,
                                                 torch::autograd::variable_list grad) {
    const auto saved = ctx->get_saved_variables();
    auto g = grad[0].to(static_cast<c10::ScalarType>(ctx->saved_data["type"].toInt()));
    if (saved[2].defined()) g = g * (saved[2] > 0);  // through the clamp
    g = g.contiguous();
    const int64_t G = ctx->saved_data["groups"].toInt();
    torch::Tensor grad_table, grad_addend;
    if (G > 0) grad_addend = g.view({g.size(0), -1, G}).sum(1);
    if (ctx->saved_data.count("sink")) {
      auto sink = ctx->saved_data["sink"].toTensor();
      gather_backward_cpu(g, saved[0], saved[1], sink);
    } else {
      grad_table = torch::zeros({ctx->saved_data["rows"].toInt(), g.size(1)}, g.options());
      gather_backward_cpu(g, saved[0], saved[1], grad_table);
    }
    return {grad_table,      torch::Tensor(), torch::Tensor(), grad_addend,
            torch::Tensor(), torch::Tensor(), torch::Tensor()};
  }
};

// One axis of the composed interpolation for one position x on an image axis of size S, map
// axis of size s: the texels idx and weights w (3, or 2 when s == S); the same operations in the
// same precision as the tensor form (axis_taps_tensors).
template <class T>
int axis_taps(T x, int64_t s, int64_t S, int64_t* idx, T* w) {
  x = x >= T(0) ? std::min(x, static_cast<T>(S - 1)) : T(0);  // NaN -> 0, never out of range
  const T i0 = std::min(std::max(std::floor(x), T(0)), static_cast<T>(std::max<int64_t>(S - 2, 0)));
  const T f = x - i0;
  if (s == S) {
    const auto j = static_cast<int64_t>(i0);
    idx[0] = j;
    idx[1] = std::min(j + 1, S - 1);
    w[0] = 1 - f;
    w[1] = f;
    return 2;
  }
  const T scale =
      static_cast<T>(S > 1 ? static_cast<double>(s - 1) / static_cast<double>(S - 1) : 0.0);
  const T X0 = i0 * scale, X1 = (i0 + 1) * scale;
  const T j0 = std::min(std::floor(X0), static_cast<T>(s - 1));
  const T j1 = std::min(std::floor(X1), static_cast<T>(s - 1));
  const T l0 = std::min(std::max(X0 - j0, T(0)), T(1));
  const T l1 = std::min(std::max(X1 - j1, T(0)), T(1));
  const int p0 = j0 < static_cast<T>(s - 1), p1 = j1 < static_cast<T>(s - 1);
  const int d = static_cast<int>(j1 - j0);
  w[0] = w[1] = w[2] = 0;
  w[0] += (1 - f) * (1 - l0);
  w[p0] += (1 - f) * l0;
  w[d] += f * (1 - l1);
  w[d + p1] += f * l1;
  const auto j = static_cast<int64_t>(j0);
  for (int k = 0; k < 3; ++k) idx[k] = std::min(j + k, s - 1);
  return 3;
}

Taps level_taps_cpu(const torch::Tensor& uv, const torch::Tensor& view, const TapLayout& layout) {
  const int64_t H = layout.height, W = layout.width;
  int64_t T_ = 0;
  for (const auto& [h, w] : layout.sizes) T_ += (h == H && w == W) ? 4 : 9;
  const int64_t M = uv.size(0);
  const auto uvc = uv.contiguous();
  const auto vc = view.to(torch::kLong).contiguous();
  Taps taps{torch::empty({M, T_}, vc.options()), torch::empty({M, T_}, uv.options())};
  // per map and axis about 12 operations; a product per tap
  render::count_work(double(M) * (24 * double(layout.sizes.size()) + double(T_)),
                     bytes_of(uvc) + bytes_of(vc) + bytes_of(taps.index) + bytes_of(taps.weight));
  AT_DISPATCH_FLOATING_TYPES(uv.scalar_type(), "level_taps", [&] {
    const scalar_t* p = uvc.data_ptr<scalar_t>();
    const int64_t* v = vc.data_ptr<int64_t>();
    int64_t* oi = taps.index.data_ptr<int64_t>();
    scalar_t* ow = taps.weight.data_ptr<scalar_t>();
    at::parallel_for(0, M, 1024, [&](int64_t begin, int64_t end) {
      for (int64_t m = begin; m < end; ++m) {
        int64_t* ti = oi + m * T_;
        scalar_t* tw = ow + m * T_;
        for (size_t l = 0; l < layout.sizes.size(); ++l) {
          const auto [h, w] = layout.sizes[l];
          int64_t ix[3], iy[3];
          scalar_t wx[3], wy[3];
          const int nx = axis_taps<scalar_t>(p[2 * m], w, W, ix, wx);
          const int ny = axis_taps<scalar_t>(p[2 * m + 1], h, H, iy, wy);
          const int64_t base = v[m] * h * w + layout.row_offsets[l];
          for (int a = 0; a < ny; ++a)
            for (int b = 0; b < nx; ++b) {
              *ti++ = base + iy[a] * w + ix[b];
              *tw++ = wy[a] * wx[b];
            }
        }
      }
    });
  });
  return taps;
}

// One axis of the composed interpolation. x: (M) positions on the image axis of size S; the
// map axis has size s. Returns (index (M, k), weight (M, k)) over map texels, k = 3 (k = 2 when
// s == S, where upsampling is the identity).
std::pair<torch::Tensor, torch::Tensor> axis_taps_tensors(const torch::Tensor& x_in, int64_t s,
                                                          int64_t S) {
  // grid_sample, border padding: clamp to the image, then the two neighbouring image pixels.
  // NaN (a non-finite camera or point) reads texel 0 instead of an index out of range.
  const auto x = torch::nan_to_num(x_in, 0.0).clamp(0, static_cast<double>(S - 1));
  const auto i0 = x.floor().clamp(0, static_cast<double>(std::max<int64_t>(S - 2, 0)));
  const auto f = x - i0;
  if (s == S) {
    const auto j = i0.to(torch::kLong);
    return {torch::stack({j, (j + 1).clamp_max(S - 1)}, 1), torch::stack({1 - f, f}, 1)};
  }
  // upsample_bilinear2d(align_corners=true): image pixel i reads the map at X = i * scale, with
  // scale computed in the working precision as ATen does; texels floor(X) and floor(X) + 1
  // (the latter only inside the map).
  const double scale_d = S > 1 ? static_cast<double>(s - 1) / static_cast<double>(S - 1) : 0.0;
  const auto scale = torch::scalar_tensor(scale_d, x.options());
  const auto X0 = i0 * scale;
  const auto X1 = (i0 + 1) * scale;
  const auto j0 = X0.floor().clamp_max(static_cast<double>(s - 1));
  const auto j1 = X1.floor().clamp_max(static_cast<double>(s - 1));
  const auto l0 = (X0 - j0).clamp(0, 1);
  const auto l1 = (X1 - j1).clamp(0, 1);
  const auto p0 = (j0 < static_cast<double>(s - 1)).to(torch::kLong);
  const auto p1 = (j1 < static_cast<double>(s - 1)).to(torch::kLong);
  const auto d = (j1 - j0).to(torch::kLong);  // 0 or 1 since scale <= 1
  // Four (offset, weight) contributions relative to j0, merged into offsets 0, 1, 2.
  const auto offsets = torch::stack({torch::zeros_like(d), p0, d, d + p1}, 1);
  const auto values = torch::stack({(1 - f) * (1 - l0), (1 - f) * l0, f * (1 - l1), f * l1}, 1);
  auto weight = torch::zeros({x.size(0), 3}, x.options()).scatter_add_(1, offsets, values);
  auto index = (j0.to(torch::kLong).unsqueeze(1) + torch::arange(3, d.options())).clamp_max(s - 1);
  return {index, weight};
}

// The taps of one map in LibTorch operations: the texels of the map of size (h, w) whose table
// starts at `row_offset`.
Taps map_taps_tensors(const torch::Tensor& uv, const torch::Tensor& view, int64_t h, int64_t w,
                      int64_t H, int64_t W, int64_t row_offset) {
  auto [ix, wx] = axis_taps_tensors(uv.select(1, 0), w, W);
  auto [iy, wy] = axis_taps_tensors(uv.select(1, 1), h, H);
  const auto base = view.to(torch::kLong) * (h * w) + row_offset;
  Taps taps;
  taps.index = (base.view({-1, 1, 1}) + iy.unsqueeze(2) * w + ix.unsqueeze(1)).flatten(1);
  taps.weight = (wy.unsqueeze(2) * wx.unsqueeze(1)).flatten(1).contiguous();
  return taps;
}

}  // namespace

Taps level_taps(const torch::Tensor& uv, const torch::Tensor& view, const TapLayout& layout) {
  TORCH_CHECK(layout.sizes.size() == layout.row_offsets.size(), "one row offset per map");
  TORCH_CHECK(uv.dim() == 2 && uv.size(1) == 2, "uv must be (M, 2), got ", uv.sizes());
  TORCH_CHECK(view.dim() == 1 && view.size(0) == uv.size(0), "view must be (M), got ",
              view.sizes());
  for (const auto& [h, w] : layout.sizes)
    TORCH_CHECK(h <= layout.height && w <= layout.width, "feature map (", h, ", ", w,
                ") larger than the image (", layout.height, ", ", layout.width, ")");
  if (cpu_kernels(uv.device())) return level_taps_cpu(uv, view, layout);
  std::vector<torch::Tensor> index, weight;
  for (size_t l = 0; l < layout.sizes.size(); ++l) {
    const auto t = map_taps_tensors(uv, view, layout.sizes[l].first, layout.sizes[l].second,
                                    layout.height, layout.width, layout.row_offsets[l]);
    index.push_back(t.index);
    weight.push_back(t.weight);
  }
  return {torch::cat(index, 1), torch::cat(weight, 1)};
}

torch::Tensor weighted_gather(const torch::Tensor& table, const Taps& taps,
                              const torch::Tensor& grad_sink, const GatherEpilogue& epilogue) {
  TORCH_CHECK(table.dim() == 2, "table must be (R, C), got ", table.sizes());
  TORCH_CHECK(taps.index.sizes() == taps.weight.sizes(), "taps index ", taps.index.sizes(),
              " and weight ", taps.weight.sizes(), " differ");
  const auto& addend = epilogue.addend;
  if (addend.defined())
    TORCH_CHECK(addend.dim() == 2 && addend.size(0) == taps.index.size(0) && addend.size(1) > 0 &&
                    table.size(1) % addend.size(1) == 0,
                "gather addend must be (", taps.index.size(0), ", G) with G dividing ",
                table.size(1), ", got ", addend.sizes());
  const auto sums = sum_type(table);
  const auto dtype = epilogue.dtype.value_or(sums);
  TORCH_CHECK(dtype == sums || (dtype == torch::kBFloat16 && sums == torch::kFloat),
              "weighted_gather writes its sums' type, or bf16 from fp32 sums; asked for ", dtype,
              " from a ", table.scalar_type(), " table");
  TORCH_CHECK(
      table.scalar_type() != torch::kBFloat16 || (!table.requires_grad() && !grad_sink.defined()),
      "weighted_gather: a bf16 table is read only (no gradient)");
  const auto weight = taps.weight.to(sums).contiguous();
  if (!cpu_kernels(table.device())) {
    // gather, weight, sum (autograd through index_select), then the epilogue
    const auto M = taps.index.size(0), T_ = taps.index.size(1);
    auto out =
        (table.index_select(0, taps.index.flatten()).view({M, T_, -1}) * weight.unsqueeze(-1))
            .sum(1);
    if (addend.defined())
      out = (out.view({M, -1, addend.size(1)}) + addend.to(out.dtype()).unsqueeze(1)).view({M, -1});
    if (epilogue.relu) out = out.relu();
    return out.to(dtype);
  }
  if (grad_sink.defined())
    TORCH_CHECK(grad_sink.sizes() == table.sizes() && grad_sink.is_contiguous(),
                "gradient sink must be a contiguous tensor shaped like the table ", table.sizes());
  {  // the taps, the rows they touch (at most the table), the addend, the output
    const double M = double(taps.index.size(0)), T_ = double(taps.index.size(1)),
                 C = double(table.size(1)), e = double(table.element_size());
    const double rows = std::min(M * T_, double(table.size(0)));
    render::count_work(M * C * (2 * T_ + (addend.defined() ? 1 : 0) + (epilogue.relu ? 1 : 0)),
                       bytes_of(taps.index) + bytes_of(weight) + rows * C * e + bytes_of(addend) +
                           M * C * double(c10::elementSize(dtype)));
  }
  return WeightedGather::apply(
      table.contiguous(), taps.index.contiguous(), weight,
      addend.defined() ? addend.to(sums).contiguous() : torch::empty({0}, table.options()),
      grad_sink.defined() ? c10::optional<torch::Tensor>(grad_sink) : c10::nullopt, epilogue.relu,
      static_cast<int64_t>(dtype));
}

}  // namespace th::model::kernels
