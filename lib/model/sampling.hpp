#pragma once
// Exact bilinear sampling of feature maps that the reference upsamples to the image size
// first (METHOD 3.1, 9): grid_sample(upsample_bilinear(map, (H, W), align_corners=true), uv,
// bilinear, border, align_corners=true) read directly from the (h, w) map, so the upsampled
// (V, C, H, W) tensor is never materialised. Each point reads 3 x 3 texels of the low-resolution
// map (2 x 2 when the map already has the image size). The CPU kernels of the same taps and the
// gathers that read them: model/kernels/gather.hpp.

#include <torch/types.h>

#include <cstdint>
#include <functional>
#include <utility>
#include <vector>

#include "model/kernels/gather.hpp"

namespace th::model {

// Taps into a channels-last table of V maps of size (h, w) (rows ordered view, y, x), plus
// `row_offset`, for sampling at image positions of an (H, W) image.
// uv: (M, 2) pixel coordinates (x, y) of the image; view: (M) int64 view of each point.
// Requires h <= H and w <= W.
Taps upsampled_bilinear_taps(const torch::Tensor& uv, const torch::Tensor& view, int64_t h,
                             int64_t w, int64_t H, int64_t W, int64_t row_offset = 0);

// Concatenates the taps of several tables stacked into one (same M): (M, T1 + T2 + ...).
Taps concat_taps(const std::vector<Taps>& taps);

// What a stage of the per-frame state shows of its tensors: fn(tensor, its gradient-sink slot,
// or null when it has none).
using TensorVisitor = std::function<void(torch::Tensor& tensor, torch::Tensor* grad_sink)>;

// (V, C, h, w) map -> (V * h * w, C) channels-last table for weighted_gather.
torch::Tensor to_table(const torch::Tensor& map);

}  // namespace th::model
