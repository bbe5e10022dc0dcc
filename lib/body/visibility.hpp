#pragma once
// Visibility of body vertices in a view (METHOD 2.4): a vertex is visible when the body mesh does
// not occlude it, decided with a z-buffer of the mesh at the working resolution. This replaces
// the precomputed per-view files the reference implementation reads (also supported:
// load_visibility_file).

#include <torch/types.h>

#include <filesystem>

namespace th::body {

struct VisibilityOptions {
  double depth_tolerance = 0.01;  // metres: a vertex this far behind the z-buffer still counts
};

// vertices: (Nv, 3) world; faces: (F, 3); K (3, 3), R (3, 3), T (3, 1) metres for an image of
// width x height. Returns (Nv) bool. Vertices projecting outside the image are invisible.
torch::Tensor vertex_visibility(const torch::Tensor& vertices, const torch::Tensor& faces,
                                const torch::Tensor& K, const torch::Tensor& R,
                                const torch::Tensor& T, int width, int height,
                                const VisibilityOptions& options = {});

// NHP's precomputed files: <root>/<human>/visibility/<camera folder>/<frame>.npy, bool (Nv,).
torch::Tensor load_visibility_file(const std::filesystem::path& file, int64_t num_vertices);

}  // namespace th::body
