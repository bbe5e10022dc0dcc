#pragma once
// A CPU triangle z-buffer rasteriser: for each pixel, the nearest triangle, its depth and its
// perspective-correct barycentric coordinates. Used by the synthetic data generator (images
// and masks) and for the visibility of SMPL vertices per view (METHOD 2.4).
//
// Pixel (x, y) samples the point with pinhole coordinates exactly (x, y), i.e. pixel centres
// at integer coordinates, the convention of OpenCV and of the rays of METHOD 2.2. Triangles are
// two-sided unless listed in RasterOptions::cull. Triangles with a vertex closer than `near` to
// the camera plane are skipped (no clipping: the scenes here never reach the camera).

#include <torch/types.h>

namespace th::render {

struct RasterOptions {
  double near = 1e-3;  // metres (camera z) below which a triangle is dropped
  // Optional (F) bool: faces that are dropped when seen from behind, i.e. when their
  // outward side (counter-clockwise winding seen from outside, as SMPL's faces) points away
  // from the camera. For closed surfaces this changes nothing visible and saves work.
  torch::Tensor cull;
};

struct Raster {
  torch::Tensor depth;    // (H, W) float32 camera z of the nearest surface; +inf where empty
  torch::Tensor face_id;  // (H, W) int32 index into faces; -1 where empty
  torch::Tensor bary;     // (H, W, 3) float32 perspective-correct weights of the face's
                          // three vertices (sum to 1); 0 where empty
};

// verts_cam: (N, 3) camera coordinates (float or double); faces: (F, 3) integer vertex
// indices; K: (3, 3) intrinsics for a width x height image. Deterministic: on equal depth the
// lower face index wins.
Raster rasterize(const torch::Tensor& verts_cam, const torch::Tensor& faces, const torch::Tensor& K,
                 int width, int height, const RasterOptions& options = {});

// Interpolates per-vertex attributes over the raster: attrs (N, C) -> (H, W, C) float32,
// zero where no face covers the pixel.
torch::Tensor interpolate(const Raster& raster, const torch::Tensor& faces,
                          const torch::Tensor& attrs);

}  // namespace th::render
