#pragma once
// Weighted gathers of table rows and the bilinear taps that address them (METHOD 3.1, 9). On CPU
// one-pass kernels (the gather with its own backward and an optional gradient sink); on other
// devices the same arithmetic in LibTorch operations.

#include <torch/types.h>

#include <cstdint>
#include <utility>
#include <vector>

namespace th::model {

// Taps of a weighted gather: out[m] = sum_t weight[m, t] * table[index[m, t]].
struct Taps {
  torch::Tensor index;   // (M, T) int64, rows of the table
  torch::Tensor weight;  // (M, T), dtype of the sampled positions
};

namespace kernels {

// The maps a point's taps read: each map's size (h, w) and the first row of its table (0 for
// separate tables, cumulative for stacked ones), for points given in pixels of an (H, W) image.
// Each map must be no larger than the image.
struct TapLayout {
  std::vector<std::pair<int64_t, int64_t>> sizes;
  std::vector<int64_t> row_offsets;
  int64_t height = 0, width = 0;
};

// The taps of every map of `layout`, (M, sum T_l): grid_sample (bilinear, border padding,
// align_corners) of the map bilinearly upsampled to the image size, read from the map itself
// (T = 9 per map, 4 where the map has the image size). uv: (M, 2) pixel coordinates (x, y);
// view: (M) int64 view of each point.
Taps level_taps(const torch::Tensor& uv, const torch::Tensor& view, const TapLayout& layout);

// What a gather does to each row before it writes it, in this order: adds `addend` (M, G) to
// each of the row's C / G groups of G channels, clamps at zero (`relu`), and writes the row in
// `dtype` (bf16: rounded once; the sums run in the table's type). The CPU kernel does it in the
// same pass, while the row is in cache; the LibTorch form in separate operations.
struct GatherEpilogue {
  torch::Tensor addend;
  bool relu = false;
  c10::optional<c10::ScalarType> dtype;
};

// out (M, C) = epilogue(sum_t weight[:, t] * table[index[:, t]]) with table (R, C).
// Differentiable w.r.t. `table` and the addend (the sampling positions carry no gradient in this
// model). With a `grad_sink` (a contiguous (R, C) buffer, CPU), the backward pass adds the
// table's gradient into the sink in place and gives autograd no gradient for the table: chunked
// evaluation then accumulates the touched rows only instead of materialising a full-size
// gradient per chunk.
torch::Tensor weighted_gather(const torch::Tensor& table, const Taps& taps,
                              const torch::Tensor& grad_sink = {},
                              const GatherEpilogue& epilogue = {});

}  // namespace kernels
}  // namespace th::model
