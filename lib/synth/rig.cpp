#include "synth/rig.hpp"

#include <torch/torch.h>

#include <cmath>

#include "geometry/camera.hpp"

namespace th::synth {
namespace {
constexpr double kPi = 3.14159265358979323846;

torch::Tensor vec3(double x, double y, double z) {
  return torch::tensor({x, y, z}, torch::kFloat64);
}

// Three draws in a fixed order (function arguments are evaluated in an unspecified order,
// which would make the dataset depend on the compiler).
template <class Draw>
torch::Tensor draw3(Draw draw) {
  const double x = draw();
  const double y = draw();
  const double z = draw();
  return vec3(x, y, z);
}
}  // namespace

std::vector<CameraCalib> make_ring(const SynthCameraConfig& c, int width, int height, Rng& rng) {
  std::vector<CameraCalib> ring;
  for (int i = 0; i < c.count; ++i) {
    const double angle = 2 * kPi * i / c.count + rng.uniform(-0.03, 0.03);
    const double radius = c.radius + rng.uniform(-c.radius_jitter, c.radius_jitter);
    // Alternate high and low cameras so that neighbouring views differ in elevation too.
    const double h = c.height + c.height_spread * ((i % 2) ? 0.5 : -0.5) + rng.uniform(-0.05, 0.05);
    auto eye = vec3(radius * std::cos(angle), radius * std::sin(angle), h);
    auto target = draw3([&] { return rng.uniform(-0.05, 0.05); }) + vec3(0.0, 0.0, 0.9);
    auto [R, T] = geometry::look_at(eye, target, vec3(0, 0, 1));
    // A small roll about the optical axis.
    const double roll = rng.uniform(-0.02, 0.02);
    R = torch::matmul(geometry::rodrigues(vec3(0, 0, roll)), R);
    T = -torch::matmul(R, eye).reshape({3, 1});

    const double f = c.focal * width * (1.0 + rng.uniform(-0.03, 0.03));
    const double px = width / 512.0;
    auto K = torch::tensor({f, 0.0, (width - 1) / 2.0 + rng.uniform(-4.0, 4.0) * px, 0.0,
                            f * (1.0 + rng.uniform(-0.002, 0.002)),
                            (height - 1) / 2.0 + rng.uniform(-4.0, 4.0) * px, 0.0, 0.0, 1.0},
                           torch::kFloat64)
                 .reshape({3, 3});
    const double s = c.distortion;
    auto D = torch::tensor({s * rng.uniform(-0.12, 0.05), s * rng.uniform(-0.04, 0.08),
                            s * rng.uniform(-1e-3, 1e-3), s * rng.uniform(-1e-3, 1e-3), 0.0},
                           torch::kFloat64)
                 .reshape({5, 1});
    ring.push_back({K, R, T, D});
  }
  return ring;
}

std::vector<CameraCalib> recalibrate(const std::vector<CameraCalib>& ring,
                                     const std::vector<int>& indices, const SynthCameraConfig& c,
                                     Rng& rng) {
  std::vector<CameraCalib> out;
  for (int i : indices) {
    const CameraCalib& base = ring.at(i);
    const double r = c.recalibration;
    auto centre = geometry::camera_center(base.R, base.T) + draw3([&] { return rng.normal(0, r); });
    auto turn = geometry::rodrigues(draw3([&] { return rng.normal(0, r / 3); }));
    CameraCalib cam = base;
    cam.R = torch::matmul(turn, base.R);
    cam.T = -torch::matmul(cam.R, centre).reshape({3, 1});
    out.push_back(cam);
  }
  return out;
}

std::vector<int> cameras_21(int count) {
  std::vector<int> idx;
  // Two cameras of the ring are missing (for 23: the 20th and 21st, 0-based 19 and 20).
  for (int i = 0; i < count; ++i)
    if (count < 5 || (i != count - 4 && i != count - 3)) idx.push_back(i);
  return idx;
}

}  // namespace th::synth
