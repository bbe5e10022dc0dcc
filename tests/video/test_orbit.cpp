// The orbit camera path of METHOD 7: radius from the dataset cameras, every camera looking at the
// person, the person centred and upright in every frame, and the reference code's result.

#include <torch/torch.h>

#include <catch2/catch.hpp>
#include <cmath>
#include <vector>

#include "geometry/camera.hpp"
#include "io/npy.hpp"
#include "support/test_env.hpp"
#include "video/camera_path.hpp"

using th::video::PathCamera;

namespace {

torch::Tensor vec(double x, double y, double z) {
  return torch::tensor({x, y, z}, torch::kFloat64);
}

// Dataset-like rig: cameras at `eyes` (C, 3) looking at `look` with world z up.
std::pair<torch::Tensor, torch::Tensor> rig(const torch::Tensor& eyes, const torch::Tensor& look) {
  std::vector<torch::Tensor> Rs, Ts;
  for (int64_t c = 0; c < eyes.size(0); ++c) {
    auto [R, T] = th::geometry::look_at(eyes[c], look, vec(0, 0, 1));
    Rs.push_back(R);
    Ts.push_back(T);
  }
  return {torch::stack(Rs), torch::stack(Ts)};
}

// A ZJU-MoCap-like ring: 21 cameras about 3.5 m from the person at 1.2-1.8 m height, jittered.
std::pair<torch::Tensor, torch::Tensor> zju_like_rig() {
  torch::manual_seed(5);
  const int64_t C = 21;
  auto angle =
      torch::arange(C, torch::kFloat64) * (2 * M_PI / C) + 0.1 * torch::randn({C}, torch::kFloat64);
  auto radius = 3.5 + 0.3 * torch::randn({C}, torch::kFloat64);
  auto height = 1.2 + 0.6 * torch::rand({C}, torch::kFloat64);
  auto eyes = torch::stack({radius * angle.cos(), radius * angle.sin(), height}, 1);
  return rig(eyes, vec(0.05, -0.1, 0.9));
}

// Target view's intrinsics at half resolution (512 x 512), as METHOD 2.1 scales them.
torch::Tensor target_K() {
  return torch::tensor({{560.0, 0.0, 258.5}, {0.0, 561.0, 251.0}, {0.0, 0.0, 1.0}},
                       torch::kFloat64);
}

}  // namespace

TEST_CASE("orbit radius: 1.3 x the 80th percentile of the camera centres (hand case)",
          "[video][orbit]") {
  // Four cameras at distance 3 around (0, 0, 1), all at the target's height: their y axes all
  // point down (0, 0, -1), the mean centre is (0, 0, 1), |coordinates| per axis are {0, 0, 3, 3},
  // whose 80th percentile is 3: the orbit is the circle of radius 3.9 in the plane z = 1.
  auto eyes = torch::tensor({{3.0, 0.0, 1.0}, {0.0, 3.0, 1.0}, {-3.0, 0.0, 1.0}, {0.0, -3.0, 1.0}},
                            torch::kFloat64);
  auto [R, T] = rig(eyes, vec(0, 0, 1));
  const auto orbit = th::video::make_orbit(R, T);
  CHECK(torch::allclose(orbit.center, vec(0, 0, 1), 0, 1e-12));
  CHECK(torch::allclose(orbit.up, vec(0, 0, -1), 0, 1e-12));
  CHECK(orbit.radii[1].item<double>() == Approx(3.9).margin(1e-12));
  CHECK(orbit.radii[2].item<double>() == Approx(3.9).margin(1e-12));

  const auto path = th::video::orbit_path(orbit, target_K(), vec(0, 0, 1), 8);
  REQUIRE(path.size() == 8);
  for (size_t k = 0; k < path.size(); ++k) {
    auto c = th::geometry::camera_center(path[k].R, path[k].T);
    const double theta = 2 * M_PI * double(k) / 8;
    INFO("camera " << k << " at " << c);
    // The reference's [0, sin, cos] on axes (up, a1 = z0 x up, a2 = up x a1) = (y, x) here.
    CHECK(torch::allclose(c, vec(3.9 * std::cos(theta), 3.9 * std::sin(theta), 1.0), 0, 1e-9));
  }
}

TEST_CASE("orbit cameras look at the person, centred and upright in every frame",
          "[video][orbit]") {
  auto [R, T] = zju_like_rig();
  const auto orbit = th::video::make_orbit(R, T);
  const auto body_centre = vec(0.05, -0.1, 0.9);
  // A person-sized box (0.6 x 0.4 x 1.8 m) around the body centre.
  auto corners = torch::tensor({-0.3, 0.3}, torch::kFloat64);
  auto g = torch::meshgrid({corners, corners * (2.0 / 3.0), corners * 3.0}, "ij");
  auto box = torch::stack({g[0].flatten(), g[1].flatten(), g[2].flatten()}, 1) + body_centre;

  auto centres = -torch::matmul(R.transpose(1, 2), T).squeeze(2);
  const double ring = (centres - centres.mean(0)).norm(2, 1).mean().item<double>();
  const auto K = target_K();
  const auto path = th::video::orbit_path(orbit, K, body_centre, 36);
  REQUIRE(path.size() == 36);
  for (size_t k = 0; k < path.size(); ++k) {
    INFO("frame " << k);
    const auto& cam = path[k];
    CHECK(
        torch::allclose(torch::matmul(cam.R, cam.R.t()), torch::eye(3, torch::kFloat64), 0, 1e-12));
    CHECK(torch::det(cam.R).item<double>() == Approx(1.0).margin(1e-12));
    // Looking at the person: the optical axis (row 2 of R) points at the body centre...
    auto eye = th::geometry::camera_center(cam.R, cam.T);
    auto to_body = (body_centre - eye) / (body_centre - eye).norm();
    CHECK(torch::dot(cam.R[2], to_body).item<double>() == Approx(1.0).margin(1e-12));
    // ...so it projects onto the principal point,
    auto uv = th::geometry::project_points(body_centre.reshape({1, 3}), K, cam.R, cam.T);
    CHECK(uv[0][0].item<double>() == Approx(258.5).margin(1e-6));
    CHECK(uv[0][1].item<double>() == Approx(251.0).margin(1e-6));
    // the whole person is in the 512 x 512 image, in front of the camera,
    auto box_uv = th::geometry::project_points(box, K, cam.R, cam.T);
    CHECK(box_uv.min().item<double>() > 0);
    CHECK(box_uv.max().item<double>() < 511);
    CHECK(th::geometry::world_to_camera(box, cam.R, cam.T).select(1, 2).min().item<double>() > 0.5);
    // and upright: the head (world +z) is above the feet in the image.
    auto head_feet = th::geometry::project_points(
        torch::stack({body_centre + vec(0, 0, 0.8), body_centre - vec(0, 0, 0.8)}), K, cam.R,
        cam.T);
    CHECK(head_feet[0][1].item<double>() < head_feet[1][1].item<double>() - 100);
    // At the orbit's distance: between the ring's mean radius and 1.3 x its largest.
    const double dist = (eye - orbit.center).norm().item<double>();
    CHECK(dist > ring);
    CHECK(dist < 1.3 * (centres - centres.mean(0)).norm(2, 1).max().item<double>());
  }
}

TEST_CASE("orbit equals the reference implementation's gen_path (numpy transcription)",
          "[video][orbit][python]") {
  auto [R, T] = zju_like_rig();
  const auto dir = th::test::scratch_dir("video_orbit_reference");
  const auto target = vec(0.05, -0.1, 0.9);
  th::io::write_npy(dir / "R.npy", R);
  th::io::write_npy(dir / "T.npy", T);
  th::io::write_npy(dir / "target.npy", target);
  th::io::write_npy(dir / "n.npy", torch::tensor({36}, torch::kInt64));
  REQUIRE(th::test::run_python("tests/video/orbit_reference.py", dir.string()) == 0);
  auto w2c = th::io::read_npy(dir / "w2c.npy");
  auto radii = th::io::read_npy(dir / "radii.npy");

  const auto orbit = th::video::make_orbit(R, T);
  CHECK(torch::allclose(orbit.radii, radii, 0, 1e-12));
  const auto path = th::video::orbit_path(orbit, target_K(), target, 36);
  for (int k = 0; k < 36; ++k) {
    INFO("frame " << k);
    CHECK(torch::allclose(path[k].R, w2c[k].slice(0, 0, 3).slice(1, 0, 3), 0, 1e-9));
    CHECK(torch::allclose(path[k].T, w2c[k].slice(0, 0, 3).slice(1, 3, 4), 0, 1e-9));
  }
}
