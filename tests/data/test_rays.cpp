#include <catch2/catch.hpp>
#include <fstream>
#include <opencv2/imgproc.hpp>

#include "core/error.hpp"
#include "data/rays.hpp"
#include "support/test_env.hpp"

using namespace th::data;

namespace {

torch::Tensor unit_box() {  // [-1, 1]^3 before the 0.01 padding
  return torch::tensor({-1.0, -1.0, -1.0, 1.0, 1.0, 1.0}, torch::kFloat64).reshape({2, 3});
}

NearFar one_ray(std::vector<double> o, std::vector<double> d) {
  return near_far(torch::tensor(o, torch::kFloat64).reshape({1, 3}),
                  torch::tensor(d, torch::kFloat64).reshape({1, 3}), unit_box());
}

}  // namespace

TEST_CASE("a ray through the box centre is valid with near/far at the padded faces", "[rays]") {
  const auto r = one_ray({0, 0, -5}, {0, 0, 2});  // |d| = 2: near/far are in units of d
  REQUIRE(r.valid.item<bool>());
  CHECK(r.near.item<double>() == Approx((5 - 1.01) / 2).epsilon(1e-12));
  CHECK(r.far.item<double>() == Approx((5 + 1.01) / 2).epsilon(1e-12));
}

TEST_CASE("a ray that misses the box is invalid", "[rays]") {
  CHECK_FALSE(one_ray({0, 3, -5}, {0, 0, 1}).valid.item<bool>());
  CHECK_FALSE(one_ray({0, 0, -5}, {1, 1, 0.2}).valid.item<bool>());
}

TEST_CASE("near/far edge cases follow the reference's rules", "[rays]") {
  // Axis-parallel ray: zero components become 1e-5 and the ray still hits.
  const auto axis = one_ray({0.3, -0.2, -4}, {0, 0, 1});
  CHECK(axis.valid.item<bool>());
  // Along an edge of the padded box: the two side planes give no point inside, the z planes two.
  CHECK(one_ray({-1.01, -1.01, -4}, {0, 0, 1}).valid.item<bool>());
  // Through two opposite corners: all six plane hits lie in the box -> invalid (reference rule).
  CHECK_FALSE(one_ray({-4, -4, -4}, {1, 1, 1}).valid.item<bool>());
  // Origin inside the box: both intersections still count, distances are unsigned.
  const auto inside = one_ray({0, 0, 0.5}, {0, 0, 1});
  REQUIRE(inside.valid.item<bool>());
  CHECK(inside.near.item<double>() == Approx(0.51));
  CHECK(inside.far.item<double>() == Approx(1.51));
  // Box entirely behind the camera: also "valid" (the reference does not check the sign).
  CHECK(one_ray({0, 0, 5}, {0, 0, 1}).valid.item<bool>());
}

TEST_CASE("near/far equals an independent numpy implementation on random rays", "[rays][python]") {
  const auto dir = th::test::scratch_dir("rays_numpy");
  torch::manual_seed(3);
  const int n = 2000;
  auto o = torch::randn({n, 3}, torch::kFloat64) * 3;
  // Mostly aimed at the box, so that both outcomes are common.
  auto d = -o + torch::randn({n, 3}, torch::kFloat64) * 1.5;
  // Some exactly axis-parallel and some tiny components.
  d.index_put_({torch::indexing::Slice(0, 100), 0}, 0.0);
  d.index_put_({torch::indexing::Slice(100, 200), 1}, 3e-6);
  const auto box = unit_box() * torch::tensor({0.5, 1.0, 0.3}, torch::kFloat64);
  {
    std::ofstream f(dir / "rays.txt");
    f.precision(17);
    const auto od = torch::cat({o, d}, 1);
    auto a = od.accessor<double, 2>();
    for (int i = 0; i < n; ++i) {
      for (int j = 0; j < 6; ++j) f << a[i][j] << ' ';
      f << '\n';
    }
    std::ofstream b(dir / "box.txt");
    b.precision(17);
    auto bb = box.accessor<double, 2>();
    for (int i = 0; i < 2; ++i) b << bb[i][0] << ' ' << bb[i][1] << ' ' << bb[i][2] << '\n';
  }
  REQUIRE(th::test::run_python("tests/python/near_far_reference.py",
                               (dir / "rays.txt").string() + " " + (dir / "box.txt").string() +
                                   " " + (dir / "out.txt").string()) == 0);
  const auto r = near_far(o, d, box);
  std::ifstream in(dir / "out.txt");
  int valid_count = 0;
  for (int i = 0; i < n; ++i) {
    double valid, near, far;
    in >> valid >> near >> far;
    REQUIRE(bool(valid) == r.valid[i].item<bool>());
    valid_count += int(valid);
    if (valid) {
      CHECK(r.near[i].item<double>() == Approx(near).epsilon(1e-12).margin(1e-12));
      CHECK(r.far[i].item<double>() == Approx(far).epsilon(1e-12).margin(1e-12));
    }
  }
  CHECK(valid_count > 100);  // the sample exercises both outcomes
  CHECK(valid_count < n - 100);
}

TEST_CASE("pixel rays pass through their pixels and have camera depth as parameter", "[rays]") {
  const auto K =
      torch::tensor({500.0, 0.0, 128.0, 0.0, 500.0, 120.0, 0.0, 0.0, 1.0}, torch::kFloat64)
          .reshape({3, 3});
  const auto R = torch::eye(3, torch::kFloat64);
  const auto T = torch::tensor({0.1, -0.2, 3.0}, torch::kFloat64).reshape({3, 1});
  const auto px = torch::tensor({{10, 20}, {128, 120}, {255, 0}}, torch::kInt64);
  const auto rays = pixel_rays(px, K, R, T);
  // The point at t = 2 along each ray has camera depth 2 and projects to its pixel.
  const auto pts = rays.origins + 2 * rays.dirs;
  const auto cam = pts.matmul(R.t()) + T.reshape({1, 3});
  CHECK(torch::allclose(cam.select(1, 2), torch::full({3}, 2.0, torch::kFloat64)));
  const auto uv = cam.matmul(K.t());
  const auto pix = uv.slice(1, 0, 2) / uv.slice(1, 2, 3);
  CHECK(torch::allclose(pix, px.to(torch::kFloat64)));
  CHECK(pixel_grid(4, 3).size(0) == 12);
  CHECK(pixel_grid(4, 3)[5].equal(torch::tensor({1, 1}, torch::kInt64)));
}

TEST_CASE("the 2D box mask covers exactly the projections of rays that hit the box", "[rays]") {
  const auto K = torch::tensor({200.0, 0.0, 64.0, 0.0, 200.0, 64.0, 0.0, 0.0, 1.0}).reshape({3, 3});
  const double c = std::cos(0.4), s = std::sin(0.4);
  const auto R =
      torch::tensor({c, 0.0, -s, 0.0, 1.0, 0.0, s, 0.0, c}, torch::kFloat64).reshape({3, 3});
  const auto T = torch::tensor({0.0, 0.0, 5.0}, torch::kFloat64).reshape({3, 1});
  const auto box = unit_box() * 0.6;
  const cv::Mat mask = box_mask(box, K, R, T, 128, 128);
  const auto px = pixel_grid(128, 128);
  const auto rays = pixel_rays(px, K, R, T);
  const auto valid = near_far(rays.origins, rays.dirs, box).valid;
  int agree = 0, total = 128 * 128;
  auto v = valid.accessor<bool, 1>();
  for (int i = 0; i < total; ++i) agree += (mask.at<uint8_t>(i / 128, i % 128) != 0) == v[i];
  // Only the one-pixel rim differs (integer rounding of the corners and the 0.01 padding).
  CHECK(cv::countNonZero(mask) > 500);
  CHECK(double(agree) / total > 0.98);
}

TEST_CASE("patch centres fall on the person about 80% of the time", "[rays][patches]") {
  cv::Mat body = cv::Mat::zeros(200, 200, CV_8U), box = cv::Mat::zeros(200, 200, CV_8U);
  cv::rectangle(box, cv::Rect(20, 20, 160, 160), cv::Scalar(1), cv::FILLED);
  cv::circle(body, cv::Point(100, 100), 40, cv::Scalar(1), cv::FILLED);
  std::mt19937_64 rng(7);
  int on_body = 0, total = 0;
  for (int it = 0; it < 1000; ++it) {
    for (const auto& p : sample_patches(body, box, 6, 20, 0.8, rng)) {
      REQUIRE(p.x0 >= 0);
      REQUIRE(p.y0 >= 0);
      REQUIRE(p.x0 + p.width <= 200);
      REQUIRE(p.y0 + p.height <= 200);
      REQUIRE(p.width <= 20);
      const int cx = std::min(p.x0 + 10, 199), cy = std::min(p.y0 + 10, 199);
      on_body += body.at<uint8_t>(cy, cx) != 0;
      ++total;
    }
  }
  const double frac = double(on_body) / total;
  INFO("fraction of patch centres on the person: " << frac);
  CHECK(frac == Approx(0.8).margin(0.02));
}

TEST_CASE("patches near the border are clipped to the image", "[rays][patches]") {
  cv::Mat body = cv::Mat::zeros(50, 50, CV_8U), box = cv::Mat::zeros(50, 50, CV_8U);
  body.at<uint8_t>(0, 0) = 1;  // the only person pixel, in the corner
  std::mt19937_64 rng(1);
  const auto patches = sample_patches(body, box, 6, 20, 1.0, rng);
  REQUIRE(patches.size() == 6);
  CHECK(patches[0].x0 == 0);
  CHECK(patches[0].width == 10);
  CHECK(patches[0].height == 10);
  cv::Mat empty = cv::Mat::zeros(50, 50, CV_8U);
  CHECK_THROWS_AS(sample_patches(empty, empty, 6, 20, 0.8, rng), th::Error);
}

TEST_CASE("bounds are the vertex AABB padded on z only", "[rays]") {
  const auto v = torch::tensor({0.0, 1.0, 2.0, -1.0, 0.5, 3.0}, torch::kFloat64).reshape({2, 3});
  const auto b = bounds_of(v, 0.05);
  CHECK(torch::allclose(
      b, torch::tensor({-1.0, 0.5, 1.95, 0.0, 1.0, 3.05}, torch::kFloat64).reshape({2, 3})));
}
