#pragma once
// Camera geometry shared by the whole project (METHOD 2.2): rotations, world -> camera,
// pinhole projection and OpenCV's lens distortion model. Everything else (ray generation,
// visibility, the synthetic generator, free-viewpoint video) calls these instead of
// re-deriving the formulas.
//
// Conventions: OpenCV cameras (x right, y down, z forward), x_cam = R x_world + T,
// uv = (K x_cam)[:2] / z with pixel centres at integer coordinates. All functions take and
// return float64 tensors (inputs of other float types are converted).

#include <torch/types.h>

#include <opencv2/core.hpp>
#include <utility>

namespace th::geometry {

// ---- rotations -----------------------------------------------------------------------------

// rvec: (..., 3) axis-angle; returns (..., 3, 3) rotation matrices (Rodrigues' formula,
// with a Taylor expansion near zero angle so that tiny rotations stay exact).
torch::Tensor rodrigues(const torch::Tensor& rvec);

// R: (..., 3, 3) rotation matrices; returns (..., 3) axis-angle with angle in [0, pi], the
// inverse of rodrigues (log map; stable near 0 and near pi).
torch::Tensor axis_angle(const torch::Tensor& R);

// ---- rigid transforms and projection ---------------------------------------------------------

// points: (N, 3) world; R: (3, 3); T: (3, 1) or (3) in the points' units.
// Returns (N, 3) camera coordinates R x + T.
torch::Tensor world_to_camera(const torch::Tensor& points, const torch::Tensor& R,
                              const torch::Tensor& T);

// Camera centre in world coordinates, -R^T T: (3).
torch::Tensor camera_center(const torch::Tensor& R, const torch::Tensor& T);

// points_cam: (N, 3) camera coordinates (z > 0); K: (3, 3). Returns (N, 2) pinhole pixels.
torch::Tensor project(const torch::Tensor& points_cam, const torch::Tensor& K);

// The pinhole projection of world points into V cameras at once, x_cam = R x + T,
// uv = (K x_cam)[:2] / z (no lens distortion), in the points' dtype: points (N, 3), K and R
// (V, 3, 3), T (V, 3, 1) -> (V, N, 2) pixel coordinates. The network's projection (float32).
torch::Tensor project_views(const torch::Tensor& points, const torch::Tensor& K,
                            const torch::Tensor& R, const torch::Tensor& T);

// The same for one camera in float64: (N, 3) -> (N, 2).
torch::Tensor project_points(const torch::Tensor& points, const torch::Tensor& K,
                             const torch::Tensor& R, const torch::Tensor& T);

// A camera looking from `eye` at `target` with world direction `up` pointing up in the image
// (all (3)). Returns {R (3, 3), T (3, 1)} with T in the units of eye.
std::pair<torch::Tensor, torch::Tensor> look_at(const torch::Tensor& eye,
                                                const torch::Tensor& target,
                                                const torch::Tensor& up);

// ---- lens distortion (OpenCV's model, D = (k1, k2, p1, p2, k3)) --------------------------------

// xy: (N, 2) normalised pinhole coordinates x/z, y/z; D: 5 values of any shape ((5), (5, 1)).
// Returns (N, 2) distorted normalised coordinates, exactly as cv::projectPoints computes them.
torch::Tensor distort_normalized(const torch::Tensor& xy, const torch::Tensor& D);

// Inverse of distort_normalized by fixed-point iteration (cv::undistortPoints' scheme, run
// to convergence): (N, 2) distorted normalised -> (N, 2) pinhole normalised.
torch::Tensor undistort_normalized(const torch::Tensor& xy, const torch::Tensor& D,
                                   int iterations = 20);

// Pixel versions with the same K before and after (as cv::undistort uses K as the new camera
// matrix): (N, 2) pinhole pixels -> (N, 2) pixels in the distorted image, and back.
torch::Tensor distort_pixels(const torch::Tensor& uv, const torch::Tensor& K,
                             const torch::Tensor& D);
torch::Tensor undistort_pixels(const torch::Tensor& uv, const torch::Tensor& K,
                               const torch::Tensor& D);

// Maps for cv::remap that turn a pinhole image into the image the distorting lens would
// record (the inverse of cv::undistort(img, K, D)): for each pixel of the distorted image,
// the pinhole pixel it sees, found with cv::undistortPoints. Returns {map_x, map_y}, CV_32F,
// height x width.
std::pair<cv::Mat, cv::Mat> distortion_maps(const torch::Tensor& K, const torch::Tensor& D,
                                            int width, int height);

// Applies the maps above: pinhole image -> distorted image (borders outside the pinhole
// image become 0). interpolation: cv::INTER_LINEAR for images, cv::INTER_NEAREST for labels.
cv::Mat distort_image(const cv::Mat& pinhole, const std::pair<cv::Mat, cv::Mat>& maps,
                      int interpolation);

// ---- conversions -------------------------------------------------------------------------

// (3, 3) or (5, 1)-like tensor -> CV_64F cv::Mat of the same shape (K, D for OpenCV calls).
cv::Mat to_cv(const torch::Tensor& t);

}  // namespace th::geometry
