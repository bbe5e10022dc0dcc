#pragma once
// Camera rays, their near/far against the human's box, the 2D box mask and the training patch
// sampler (METHOD 2.2, 5).

#include <torch/types.h>

#include <array>
#include <cstdint>
#include <opencv2/core.hpp>
#include <random>
#include <vector>

namespace th::data {

// An axis-aligned box in world coordinates: (2, 3) float64, rows min and max.
// bounds_of(vertices (V, 3), pad_z): the AABB of a frame's vertices padded on z only (METHOD 2.2).
torch::Tensor bounds_of(const torch::Tensor& vertices, double pad_z);

// Rays through integer pixel centres (METHOD 2.2): origins o = -R^T T and directions
// d = R^T K^-1 [x, y, 1]^T, not normalised (t equals camera depth).
// pixels: (N, 2) float/int (x, y); returns {origins (N, 3), dirs (N, 3)} float64.
struct RayBundle {
  torch::Tensor origins;
  torch::Tensor dirs;
};
RayBundle pixel_rays(const torch::Tensor& pixels, const torch::Tensor& K, const torch::Tensor& R,
                     const torch::Tensor& T);
// Every pixel of a width x height image, row-major: pixels (H*W, 2) int64 (x, y).
torch::Tensor pixel_grid(int width, int height);

// Near/far of rays against the box (METHOD 2.2, reference behaviour kept): the box is padded by
// 0.01, direction components with |d| < 1e-5 become +1e-5, the 6 plane intersections are
// computed and a ray is valid iff exactly two of them lie in the box (+-1e-6); near/far are
// the distances from the origin to those two points divided by |d| (with the adjusted d).
// origins, dirs: (N, 3); box: (2, 3). Returns near, far (N) float64 (0 where invalid) and
// valid (N) bool.
struct NearFar {
  torch::Tensor near;
  torch::Tensor far;
  torch::Tensor valid;
};
NearFar near_far(const torch::Tensor& origins, const torch::Tensor& dirs, const torch::Tensor& box);
// One ray of near_far: origin o, direction d, box {min x, y, z, max x, y, z} (unpadded). False
// (near = far = 0) when the ray misses the box.
bool near_far_ray(const double o[3], const double d[3], const std::array<double, 6>& box,
                  double& near, double& far);

// The box's silhouette: project the 8 corners, fill the 6 faces. CV_8U, 1 inside.
cv::Mat box_mask(const torch::Tensor& box, const torch::Tensor& K, const torch::Tensor& R,
                 const torch::Tensor& T, int width, int height);

// Training patches (METHOD 5): `count` squares of side `size`; each centre drawn uniformly from
// the person's pixels with probability body_prob, otherwise from the in-box background; the
// square is clipped to the image. Patches may overlap.
struct Patch {
  int x0, y0, width, height;  // clipped rectangle in pixels
};
// body: CV_8U mask (non-zero = person); box: CV_8U box mask. Falls back to the other pool when
// one pool is empty; throws th::Error when both are.
std::vector<Patch> sample_patches(const cv::Mat& body, const cv::Mat& box, int count, int size,
                                  double body_prob, std::mt19937_64& rng);

}  // namespace th::data
