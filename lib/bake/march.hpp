#pragma once
// Rendering a baked frame (METHOD 7.1): every pixel's ray, its near/far against the frame's box,
// and its samples exactly as the exact renderer makes them (METHOD 2.2, 4), but each sample's
// density interpolated trilinearly from the grid, and its colour weighted by the corners'
// positive density, instead of asked of the network; the same compositing, black background, and
// early termination once the transmittance falls below a bound. Rows are shared among the intra-op
// threads (at::parallel_for), a band of rows at a time, so that a caller can stop a long march
// between bands.

#include <torch/types.h>

#include <cstdint>
#include <functional>
#include <optional>

#include "bake/baked_frame.hpp"

namespace th::bake {

struct MarchOptions {
  int samples = 64;           // per ray, as render.samples
  double termination = 1e-4;  // stop a ray once its transmittance is below this (0: never)
  int color_set = 0;          // which of the bake's colour sets (BakedFrame::eyes) to show
};

struct MarchStats {
  int64_t rays = 0;        // rays that meet the box
  int64_t samples = 0;     // samples looked up
  int64_t occupied = 0;    // samples inside a stored brick
  int64_t terminated = 0;  // rays stopped early
};

struct BakedImages {
  torch::Tensor rgb;    // (H, W, 3) float32 in [0, 1]
  torch::Tensor depth;  // (H, W) float32: sum of weight x camera depth, 0 outside the box
  torch::Tensor acc;    // (H, W) float32: accumulated opacity
  MarchStats stats;
};

// The view of pinhole camera K (3, 3), R (3, 3), T (3, 1) (float64, metres, OpenCV axes) at
// width x height.
BakedImages render_baked(const BakedFrame& frame, const torch::Tensor& K, const torch::Tensor& R,
                         const torch::Tensor& T, int width, int height,
                         const MarchOptions& options);

// As above, asking `cancelled` on the calling thread between bands of rows (about 2^18 samples
// per intra-op thread each): nullopt once it says true. The pixels are those above.
std::optional<BakedImages> render_baked(const BakedFrame& frame, const torch::Tensor& K,
                                        const torch::Tensor& R, const torch::Tensor& T, int width,
                                        int height, const MarchOptions& options,
                                        const std::function<bool()>& cancelled);

}  // namespace th::bake
