#include "data/calibration.hpp"

#include <fmt/format.h>
#include <torch/torch.h>

#include <cmath>

namespace th::data {

std::string unusable_intrinsics(const torch::Tensor& K) {
  const auto k = K.to(torch::kFloat64).contiguous();
  const double* a = k.data_ptr<double>();
  if (!(std::isfinite(a[0]) && a[0] > 0 && std::isfinite(a[4]) && a[4] > 0))
    return fmt::format("K has focal lengths fx = {}, fy = {} (both must be positive)", a[0], a[4]);
  // With its last row (0, 0, 1) and K[1][0] = 0, K is upper triangular: invertible.
  if (!(std::abs(a[3]) <= 1e-9 && std::abs(a[6]) <= 1e-9 && std::abs(a[7]) <= 1e-9 &&
        std::abs(a[8] - 1) <= 1e-9) ||
      !std::isfinite(a[1]) || !std::isfinite(a[2]) || !std::isfinite(a[5]))
    return fmt::format(
        "K is not an intrinsic matrix (rows [{} {} {}] [{} {} {}] [{} {} {}]; expected [fx s cx] "
        "[0 fy cy] [0 0 1])",
        a[0], a[1], a[2], a[3], a[4], a[5], a[6], a[7], a[8]);
  return "";
}

std::string implausible_rotation(const torch::Tensor& R) {
  const auto r = R.to(torch::kFloat64).contiguous();
  const double off =
      (torch::mm(r, r.t()) - torch::eye(3, torch::kFloat64)).abs().max().item<double>();
  const double det = torch::det(r).item<double>();
  if (!(off <= CalibrationLimits::kRotation) ||
      !(std::abs(det - 1) <= CalibrationLimits::kRotation))
    return fmt::format("R is not a rotation (|R R^T - I| = {:.3g}, det R = {:.4g}; tolerance {})",
                       off, det, CalibrationLimits::kRotation);
  return "";
}

std::string implausible_view(const torch::Tensor& vertices, const torch::Tensor& K,
                             const torch::Tensor& R, const torch::Tensor& T, int width,
                             int height) {
  const auto v = vertices.to(torch::kFloat64);
  const auto k = K.to(torch::kFloat64), r = R.to(torch::kFloat64),
             t = T.to(torch::kFloat64).reshape({3, 1});
  const auto center = -torch::mm(r.t(), t).flatten();  // the camera's centre in the world
  const double distance = (v.mean(0) - center).norm().item<double>();
  if (!(distance >= CalibrationLimits::kMinDistance && distance <= CalibrationLimits::kMaxDistance))
    return fmt::format(
        "the camera is {:.3g} m from the body's centre (plausible: {} to {} m; {})", distance,
        CalibrationLimits::kMinDistance, CalibrationLimits::kMaxDistance,
        distance < CalibrationLimits::kMinDistance
            ? "T in metres where the file holds millimetres, as ZJU-MoCap's annots.npy?"
            : "T in millimetres where the file holds metres, as EasyMocap's extri.yml?");
  const auto cam = torch::mm(v, r.t()) + t.t();  // (N, 3) camera coordinates
  const auto z = cam.select(1, 2);
  const auto px = torch::mm(cam, k.t());
  const auto u = px.select(1, 0) / z, w = px.select(1, 1) / z;
  const auto inside = (z > 0) & (u >= 0) & (u < width) & (w >= 0) & (w < height);
  const double fraction = inside.to(torch::kFloat64).mean().item<double>();
  if (!(fraction >= CalibrationLimits::kMinInImage))
    return fmt::format(
        "only {:.1f}% of the body's vertices project into its {}x{} image (at least {:.0f}% "
        "expected)",
        100 * fraction, width, height, 100 * CalibrationLimits::kMinInImage);
  return "";
}

}  // namespace th::data
