#include "model/sampling.hpp"

#include <ATen/Parallel.h>
#include <torch/torch.h>

#include <algorithm>

namespace th::model {
namespace {

namespace F = torch::nn::functional;

// One axis of the composed interpolation. x: (M) positions on the image axis of size S; the
// map axis has size s. Returns (index (M, k), weight (M, k)) over map texels, k = 3 (k = 2 when
// s == S, where upsampling is the identity).
std::pair<torch::Tensor, torch::Tensor> axis_taps(const torch::Tensor& x_in, int64_t s, int64_t S) {
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

}  // namespace

Taps upsampled_bilinear_taps(const torch::Tensor& uv, const torch::Tensor& view, int64_t h,
                             int64_t w, int64_t H, int64_t W, int64_t row_offset) {
  TORCH_CHECK(uv.dim() == 2 && uv.size(1) == 2, "uv must be (M, 2), got ", uv.sizes());
  TORCH_CHECK(view.dim() == 1 && view.size(0) == uv.size(0), "view must be (M), got ",
              view.sizes());
  TORCH_CHECK(h <= H && w <= W, "feature map (", h, ", ", w, ") larger than the image (", H, ", ",
              W, ")");
  auto [ix, wx] = axis_taps(uv.select(1, 0), w, W);
  auto [iy, wy] = axis_taps(uv.select(1, 1), h, H);
  const auto base = view.to(torch::kLong) * (h * w) + row_offset;
  Taps taps;
  taps.index = (base.view({-1, 1, 1}) + iy.unsqueeze(2) * w + ix.unsqueeze(1)).flatten(1);
  taps.weight = (wy.unsqueeze(2) * wx.unsqueeze(1)).flatten(1).contiguous();
  return taps;
}

Taps concat_taps(const std::vector<Taps>& taps) {
  std::vector<torch::Tensor> index, weight;
  for (const auto& t : taps) {
    index.push_back(t.index);
    weight.push_back(t.weight);
  }
  return {torch::cat(index, 1), torch::cat(weight, 1)};
}

torch::Tensor to_table(const torch::Tensor& map) {
  TORCH_CHECK(map.dim() == 4, "feature map must be (V, C, h, w), got ", map.sizes());
  return map.permute({0, 2, 3, 1}).reshape({-1, map.size(1)});
}

}  // namespace th::model
