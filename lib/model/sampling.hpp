#pragma once
// Exact bilinear sampling of feature maps that the reference upsamples to the image size
// first (METHOD 3.1, 9): grid_sample(upsample_bilinear(map, (H, W), align_corners=true), uv,
// bilinear, border, align_corners=true) read directly from the (h, w) map, so the upsampled
// (V, C, H, W) tensor is never materialised. Each point reads 3 x 3 texels of the low-resolution
// map (2 x 2 when the map already has the image size).

#include <torch/types.h>

#include <cstdint>
#include <functional>
#include <utility>
#include <vector>

namespace th::model {

// Taps of a weighted gather: out[m] = sum_t weight[m, t] * table[index[m, t]].
struct Taps {
  torch::Tensor index;   // (M, T) int64, rows of the table
  torch::Tensor weight;  // (M, T), dtype of the sampled positions
};

// Taps into a channels-last table of V maps of size (h, w) (rows ordered view, y, x), plus
// `row_offset`, for sampling at image positions of an (H, W) image.
// uv: (M, 2) pixel coordinates (x, y) of the image; view: (M) int64 view of each point.
// Requires h <= H and w <= W.
Taps upsampled_bilinear_taps(const torch::Tensor& uv, const torch::Tensor& view, int64_t h,
                             int64_t w, int64_t H, int64_t W, int64_t row_offset = 0);

// The taps of several maps at once, (M, sum T_l), computed in one pass on CPU (the same
// arithmetic as upsampled_bilinear_taps, which serves other devices). sizes: (h_l, w_l) per map;
// row_offsets: added to each map's rows (0 for separate tables, cumulative for stacked ones).
Taps multi_level_taps(const torch::Tensor& uv, const torch::Tensor& view,
                      const std::vector<std::pair<int64_t, int64_t>>& sizes,
                      const std::vector<int64_t>& row_offsets, int64_t H, int64_t W);

// Concatenates the taps of several tables stacked into one (same M): (M, T1 + T2 + ...).
Taps concat_taps(const std::vector<Taps>& taps);

// out (M, C) = sum_t weight[:, t] * table[index[:, t]]. Differentiable w.r.t. `table` only (the
// sampling positions carry no gradient in this model).
// table: (R, C); returns (M, C).
// With a `grad_sink` (a (R, C) buffer, CPU), the backward pass adds the table's gradient into
// the sink in place and gives autograd no gradient for the table: chunked evaluation then
// accumulates touched rows only instead of materialising a full-size gradient per chunk.
torch::Tensor weighted_gather(const torch::Tensor& table, const Taps& taps,
                              const torch::Tensor& grad_sink = {});

// What a stage of the per-frame state shows of its tensors: fn(tensor, its gradient-sink slot,
// or null when it has none).
using TensorVisitor = std::function<void(torch::Tensor& tensor, torch::Tensor* grad_sink)>;

// (V, C, h, w) map -> (V * h * w, C) channels-last table for weighted_gather.
torch::Tensor to_table(const torch::Tensor& map);

}  // namespace th::model
