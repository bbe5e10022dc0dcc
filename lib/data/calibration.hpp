#pragma once
// Plausibility of calibration where data are read: values that cannot be right (a rotation that
// is not one, intrinsics without positive focal lengths, T in metres where millimetres are
// expected) would otherwise train and evaluate without a word.

#include <torch/types.h>

#include <string>

namespace th::data {

// The tolerances, stated once.
struct CalibrationLimits {
  static constexpr double kRotation = 1e-3;    // max |R R^T - I| and |det R - 1|
  static constexpr double kMinDistance = 0.2;  // metres from a camera's centre to the body's
  static constexpr double kMaxDistance = 100.0;
  static constexpr double kMinInImage =
      0.5;  // fraction of the body's vertices in a reference image
};

// Why intrinsics `K` (3, 3) cannot be used, or "" when they can: focal lengths positive and
// finite, K upper triangular with last row (0, 0, 1), so invertible. Always an error: no ray
// can be cast through such a camera.
std::string unusable_intrinsics(const torch::Tensor& K);

// Why `R` (3, 3) is not a rotation, or "" when it is: orthonormal with det +1 within kRotation.
std::string implausible_rotation(const torch::Tensor& R);

// Why the body `vertices` (N, 3), in world metres, cannot be seen as it should by a reference
// camera (K, R, T (3, 1)) of a `width` x `height` image, or "": its centre between kMinDistance
// and kMaxDistance from the camera, in front of it, and at least kMinInImage of the vertices
// inside the image.
std::string implausible_view(const torch::Tensor& vertices, const torch::Tensor& K,
                             const torch::Tensor& R, const torch::Tensor& T, int width, int height);

}  // namespace th::data
