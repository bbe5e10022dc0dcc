#pragma once
// Internal to lib/render: the per-sample lengths of METHOD 4's compositing, shared by composite()
// and the early-termination march of progressive rendering (which must use the same ones).

#include <torch/types.h>

namespace th::render {

// (n, S): (z_{i+1} - z_i) |d|, last 1e10 |d|. z: (n, S), directions: (n, 3).
torch::Tensor segment_lengths(const torch::Tensor& z, const torch::Tensor& directions);

}  // namespace th::render
