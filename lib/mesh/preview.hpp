#pragma once
// A shaded preview image of a mesh, rendered with the project's rasteriser (render/raster.hpp),
// for looking at a reconstruction without a 3D viewer (the mesh preview PNG).
//
// Shading: per-pixel interpolated vertex normals, a headlight plus a key light from the upper
// left, Lambertian, one-sided: back faces (an inside-out mesh) render dark, so a wrongly oriented
// mesh shows at a glance.

#include <torch/types.h>

#include <array>
#include <opencv2/core.hpp>

#include "mesh/tri_mesh.hpp"

namespace th::mesh {

struct PreviewCamera {
  torch::Tensor K;  // (3, 3) float64
  torch::Tensor R;  // (3, 3) float64, world -> camera (METHOD 2.2)
  torch::Tensor T;  // (3, 1) float64, metres
  int width = 512;
  int height = 512;
};

struct PreviewOptions {
  std::array<float, 3> color{0.80f, 0.80f, 0.82f};  // RGB in [0, 1] when the mesh has none
  std::array<float, 3> background{1.f, 1.f, 1.f};   // RGB in [0, 1]
  float ambient = 0.2f;                             // shade of surfaces facing away from light
};

// A pinhole camera that frames the whole mesh: it looks at the centre of the mesh's bounding
// box along `view_dir` (world (3), need not be unit), with world direction `up` (3) pointing up
// in the image, from far enough that the bounding sphere fits in the image with a margin.
// Principal point at the image centre, square pixels.
PreviewCamera frame_mesh(const TriMesh& mesh, const torch::Tensor& view_dir,
                         const torch::Tensor& up, int width = 512, int height = 512);

// Renders the mesh seen by `camera`; returns a BGR CV_8UC3 image (camera.height x camera.width),
// ready for cv::imwrite. Per-vertex colours are used when the mesh has them.
cv::Mat render_preview(const TriMesh& mesh, const PreviewCamera& camera,
                       const PreviewOptions& options = {});

}  // namespace th::mesh
