// Camera geometry (lib/geometry/camera): checked against OpenCV's own implementations
// (cv::Rodrigues, cv::projectPoints, cv::undistort) and hand calculations.

#include <torch/torch.h>

#include <catch2/catch.hpp>
#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>

#include "geometry/camera.hpp"

using namespace th::geometry;

namespace {

torch::Tensor K_512() {
  return torch::tensor({560.0, 0.0, 251.3, 0.0, 561.5, 258.9, 0.0, 0.0, 1.0}, torch::kFloat64)
      .reshape({3, 3});
}
torch::Tensor D_small() {
  return torch::tensor({-0.11, 0.05, 8e-4, -6e-4, 0.01}, torch::kFloat64).reshape({5, 1});
}

}  // namespace

TEST_CASE("rodrigues matches cv::Rodrigues also for tiny and large angles", "[geometry]") {
  torch::manual_seed(3);
  auto r = torch::randn({20, 3}, torch::kFloat64);
  r[0] = torch::tensor({1e-9, -2e-9, 5e-10}, torch::kFloat64);
  r[1] = torch::tensor({0.0, 0.0, 0.0}, torch::kFloat64);
  r[2] = torch::tensor({3.1, 0.2, -0.1}, torch::kFloat64);
  auto R = rodrigues(r);
  REQUIRE(R.sizes() == torch::IntArrayRef({20, 3, 3}));
  for (int i = 0; i < 20; ++i) {
    cv::Mat rv = (cv::Mat_<double>(3, 1) << r[i][0].item<double>(), r[i][1].item<double>(),
                  r[i][2].item<double>());
    cv::Mat expected;
    cv::Rodrigues(rv, expected);
    for (int a = 0; a < 3; ++a)
      for (int b = 0; b < 3; ++b)
        CHECK(R[i][a][b].item<double>() == Approx(expected.at<double>(a, b)).margin(1e-12));
  }
}

TEST_CASE("axis_angle inverts rodrigues up to pi", "[geometry]") {
  torch::manual_seed(4);
  auto dirs = torch::randn({50, 3}, torch::kFloat64);
  dirs = dirs / dirs.norm(2, 1, true);
  auto angles = torch::linspace(0.0, 3.14159, 50, torch::kFloat64).unsqueeze(1);
  auto r = dirs * angles;
  auto back = axis_angle(rodrigues(r));
  CHECK(torch::allclose(back, r, 0, 1e-7));
  // Exactly pi: the axis comes back up to sign, and it is still a rotation by pi.
  auto pi_rot = torch::tensor({0.0, 3.141592653589793, 0.0}, torch::kFloat64);
  auto again = rodrigues(axis_angle(rodrigues(pi_rot)));
  CHECK(torch::allclose(again, rodrigues(pi_rot), 0, 1e-12));
}

TEST_CASE("project_points with distortion matches cv::projectPoints", "[geometry]") {
  torch::manual_seed(5);
  auto pts = torch::rand({30, 3}, torch::kFloat64) - 0.5;
  auto rvec = torch::tensor({0.1, -0.2, 0.05}, torch::kFloat64);
  auto R = rodrigues(rvec);
  auto T = torch::tensor({0.1, -0.05, 3.0}, torch::kFloat64).reshape({3, 1});
  auto K = K_512(), D = D_small();
  auto cam = world_to_camera(pts, R, T);
  auto ours = distort_pixels(project(cam, K), K, D);

  std::vector<cv::Point3d> obj;
  for (int i = 0; i < 30; ++i)
    obj.emplace_back(pts[i][0].item<double>(), pts[i][1].item<double>(), pts[i][2].item<double>());
  std::vector<cv::Point2d> img;
  cv::projectPoints(obj, to_cv(rvec), to_cv(T), to_cv(K), to_cv(D), img);
  for (int i = 0; i < 30; ++i) {
    CHECK(ours[i][0].item<double>() == Approx(img[i].x).margin(1e-9));
    CHECK(ours[i][1].item<double>() == Approx(img[i].y).margin(1e-9));
  }
  // The undistorted pixels are the pinhole projection again.
  CHECK(torch::allclose(undistort_pixels(ours, K, D), project(cam, K), 0, 1e-8));
}

TEST_CASE("camera_center and look_at put the camera where asked looking at the target",
          "[geometry]") {
  auto eye = torch::tensor({3.0, 1.0, 1.5}, torch::kFloat64);
  auto target = torch::tensor({0.0, 0.2, 0.9}, torch::kFloat64);
  auto [R, T] = look_at(eye, target, torch::tensor({0.0, 0.0, 1.0}, torch::kFloat64));
  CHECK(torch::allclose(camera_center(R, T), eye, 0, 1e-12));
  CHECK(torch::allclose(torch::matmul(R, R.t()), torch::eye(3, torch::kFloat64), 0, 1e-12));
  CHECK(torch::det(R).item<double>() == Approx(1.0));
  // The target is on the optical axis; world up points up in the image (negative y).
  auto t_cam = world_to_camera(target.reshape({1, 3}), R, T);
  CHECK(t_cam[0][0].item<double>() == Approx(0.0).margin(1e-12));
  CHECK(t_cam[0][1].item<double>() == Approx(0.0).margin(1e-12));
  CHECK(t_cam[0][2].item<double>() > 0);
  auto above = world_to_camera(
      (target + torch::tensor({0.0, 0.0, 0.5}, torch::kFloat64)).reshape({1, 3}), R, T);
  CHECK(above[0][1].item<double>() < 0);
}

TEST_CASE("distortion maps send each distorted pixel to the pinhole pixel it shows", "[geometry]") {
  auto K = K_512(), D = D_small();
  const int w = 512, h = 512;
  auto maps = distortion_maps(K, D, w, h);
  REQUIRE(maps.first.type() == CV_32F);
  REQUIRE(maps.first.rows == h);
  REQUIRE(maps.first.cols == w);
  // Distorting the map's pinhole pixel lands on the pixel itself.
  std::vector<double> uv;
  std::vector<std::pair<int, int>> at = {{0, 0}, {100, 37}, {255, 255}, {511, 511}, {400, 20}};
  for (auto [u, v] : at) {
    uv.push_back(maps.first.at<float>(v, u));
    uv.push_back(maps.second.at<float>(v, u));
  }
  auto pin = torch::tensor(uv, torch::kFloat64).reshape({-1, 2});
  auto back = distort_pixels(pin, K, D);
  for (size_t i = 0; i < at.size(); ++i) {
    CHECK(back[i][0].item<double>() == Approx(at[i].first).margin(2e-3));
    CHECK(back[i][1].item<double>() == Approx(at[i].second).margin(2e-3));
  }
}

TEST_CASE("cv::undistort of a distorted image gives back the pinhole image", "[geometry]") {
  // A smooth pinhole image: undistort(distort(img)) must reproduce it away from the borders.
  const int w = 256, h = 256;
  auto K = K_512() * 0.5;
  K[2][2] = 1.0;
  auto D = D_small();
  cv::Mat pinhole(h, w, CV_32F);
  for (int v = 0; v < h; ++v)
    for (int u = 0; u < w; ++u)
      pinhole.at<float>(v, u) = float(0.5 + 0.25 * std::sin(u / 9.0) + 0.25 * std::cos(v / 13.0));
  auto distorted = distort_image(pinhole, distortion_maps(K, D, w, h), cv::INTER_LINEAR);
  cv::Mat back;
  cv::undistort(distorted, back, to_cv(K), to_cv(D));
  cv::Mat diff;
  cv::absdiff(back(cv::Rect(24, 24, w - 48, h - 48)), pinhole(cv::Rect(24, 24, w - 48, h - 48)),
              diff);
  double max_err = 0;
  cv::minMaxLoc(diff, nullptr, &max_err);
  CHECK(max_err < 0.01);
}
