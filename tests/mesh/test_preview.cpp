// Mesh preview rendered with the project's rasteriser: silhouette size from a hand calculation,
// Lambert shading, orientation sensitivity and vertex colours.

#include <torch/torch.h>

#include <catch2/catch.hpp>
#include <cmath>
#include <opencv2/imgcodecs.hpp>

#include "geometry/camera.hpp"
#include "mesh/marching_cubes.hpp"
#include "mesh/preview.hpp"
#include "support/test_env.hpp"

namespace {

// Unit sphere centred at the origin, from marching cubes on |p| at 48^3.
th::mesh::TriMesh unit_sphere() {
  const int64_t n = 48;
  const double lo = -1.2, s = 2.4 / (n - 1);
  auto a = lo + s * torch::arange(n, torch::kFloat64);
  auto g = torch::meshgrid({a, a, a}, "ij");
  auto field = (1.0 - (g[0].square() + g[1].square() + g[2].square()).sqrt()).to(torch::kFloat32);
  return th::mesh::marching_cubes(field, {{lo, lo, lo}, {s, s, s}}, {0.0, 1});
}

}  // namespace

TEST_CASE("preview of a sphere: disc of the predicted size, shaded, background elsewhere",
          "[mesh][preview]") {
  const auto sphere = unit_sphere();
  const auto cam = th::mesh::frame_mesh(sphere, torch::tensor({1.0, -0.5, 0.3}),
                                        torch::tensor({0.0, 0.0, 1.0}), 320, 240);
  const cv::Mat img = th::mesh::render_preview(sphere, cam);
  cv::imwrite((th::test::scratch_dir("mesh_preview") / "sphere.png").string(), img);
  REQUIRE(img.rows == 240);
  REQUIRE(img.cols == 320);
  REQUIRE(img.type() == CV_8UC3);

  // Silhouette of a unit sphere seen from distance d: a disc of radius f tan(asin(1 / d)).
  const double d = th::geometry::camera_center(cam.R, cam.T).norm().item<double>();
  const double f = cam.K[0][0].item<double>();
  const double r = f * std::tan(std::asin(1.0 / d));
  int64_t covered = 0;
  for (int y = 0; y < img.rows; ++y)
    for (int x = 0; x < img.cols; ++x)
      if (img.at<cv::Vec3b>(y, x) != cv::Vec3b(255, 255, 255)) ++covered;
  INFO("covered " << covered << " predicted " << M_PI * r * r);
  CHECK(std::abs(covered / (M_PI * r * r) - 1.0) < 0.02);
  CHECK(r < 0.5 * img.rows);  // framed: the whole sphere is in the image

  // Centre faces the camera (bright), the rim is grazing (darker); corners are background.
  const auto centre = img.at<cv::Vec3b>(img.rows / 2, img.cols / 2);
  const auto rim = img.at<cv::Vec3b>(img.rows / 2, static_cast<int>(img.cols / 2 + 0.97 * r));
  CHECK(centre[1] > 150);
  CHECK(rim[1] < centre[1] - 40);
  CHECK(img.at<cv::Vec3b>(0, 0) == cv::Vec3b(255, 255, 255));

  // Inside-out faces show as dark (one-sided shading), so a wrongly oriented mesh is visible.
  auto flipped = sphere;
  flipped.faces = sphere.faces.flip({1}).contiguous();
  const cv::Mat dark = th::mesh::render_preview(flipped, cam);
  CHECK(dark.at<cv::Vec3b>(img.rows / 2, img.cols / 2)[1] < 80);
}

TEST_CASE("preview uses vertex colours", "[mesh][preview]") {
  auto sphere = unit_sphere();
  sphere.colors =
      torch::tensor({200, 30, 10}, torch::kUInt8).expand({sphere.num_verts(), 3}).contiguous();
  const auto cam = th::mesh::frame_mesh(sphere, torch::tensor({0.0, 0.0, 1.0}),
                                        torch::tensor({0.0, -1.0, 0.0}), 64, 64);
  const cv::Mat img = th::mesh::render_preview(sphere, cam, {{0.5f, 0.5f, 0.5f}, {0.f, 0.f, 0.f}});
  const auto c = img.at<cv::Vec3b>(32, 32);  // BGR
  CHECK(c[2] > 120);
  CHECK(c[2] > 4 * c[1]);
  CHECK(img.at<cv::Vec3b>(0, 0) == cv::Vec3b(0, 0, 0));
}
