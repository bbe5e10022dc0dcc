// The two halves together, as the render app will use them: an orbit around a person-shaped
// mesh, each view rendered (here by the mesh preview instead of the network), written as frames
// and summarised in a contact sheet. The person must be centred and whole in every frame.

#include <torch/torch.h>

#include <catch2/catch.hpp>
#include <cmath>
#include <opencv2/imgcodecs.hpp>

#include "geometry/camera.hpp"
#include "mesh/marching_cubes.hpp"
#include "mesh/preview.hpp"
#include "support/test_env.hpp"
#include "video/camera_path.hpp"
#include "video/contact_sheet.hpp"
#include "video/frame_writer.hpp"

TEST_CASE("orbit frames of a person-shaped mesh: centred, whole, written, contact sheet",
          "[video][orbit][mesh]") {
  // Person: an ellipsoid 0.6 x 0.4 x 1.7 m around the body centre, as a density field.
  const auto body = torch::tensor({0.05, -0.1, 0.9}, torch::kFloat64);
  const auto grid = th::mesh::grid_over_bounds(
      torch::stack({body - torch::tensor({0.35, 0.25, 0.9}, torch::kFloat64),
                    body + torch::tensor({0.35, 0.25, 0.9}, torch::kFloat64)}),
      0.03);
  auto p = th::mesh::slab_points(grid, 0, grid.depth).to(torch::kFloat64) - body;
  auto r = (p.select(1, 0).square() / 0.09 + p.select(1, 1).square() / 0.04 +
            p.select(1, 2).square() / 0.7225)
               .sqrt();
  const auto person = th::mesh::marching_cubes(
      (40.0 * (1.5 - r)).reshape({grid.depth, grid.height, grid.width}), grid.spec, {20.0, 10});

  // A ring of 21 dataset cameras 3.5 m away, 1.5 m high, looking at the person, z up.
  std::vector<torch::Tensor> Rs, Ts;
  for (int c = 0; c < 21; ++c) {
    const double a = 2 * M_PI * c / 21;
    auto eye = torch::tensor({3.5 * std::cos(a), 3.5 * std::sin(a), 1.5}, torch::kFloat64);
    auto [R, T] = th::geometry::look_at(eye, body, torch::tensor({0.0, 0.0, 1.0}));
    Rs.push_back(R);
    Ts.push_back(T);
  }
  const auto orbit = th::video::make_orbit(torch::stack(Rs), torch::stack(Ts));
  // Target view intrinsics at 1/8 of 1024 px.
  auto K =
      torch::tensor({{140.0, 0.0, 63.5}, {0.0, 140.0, 63.5}, {0.0, 0.0, 1.0}}, torch::kFloat64);
  const int n = 12;
  const auto path = th::video::orbit_path(orbit, K, body, n);

  const auto dir = th::test::scratch_dir("video_orbit_render");
  th::video::FrameWriter writer({dir});
  for (int k = 0; k < n; ++k) {
    INFO("frame " << k);
    const cv::Mat img = th::mesh::render_preview(
        person, {path[k].K, path[k].R, path[k].T, 128, 128}, {{0.8f, 0.8f, 0.8f}, {0, 0, 0}});
    // Silhouette: centroid at the principal point (symmetric shape), nothing on the border.
    double sx = 0, sy = 0, count = 0, border = 0;
    for (int y = 0; y < img.rows; ++y)
      for (int x = 0; x < img.cols; ++x)
        if (img.at<cv::Vec3b>(y, x) != cv::Vec3b(0, 0, 0)) {
          sx += x, sy += y, ++count;
          if (x == 0 || y == 0 || x == img.cols - 1 || y == img.rows - 1) ++border;
        }
    REQUIRE(count > 500);
    CHECK(sx / count == Approx(63.5).margin(1.0));
    CHECK(sy / count == Approx(63.5).margin(1.0));
    CHECK(border == 0);
    writer.write_frame(k, img);
  }
  CHECK(writer.missing(n) == 0);
  std::vector<std::filesystem::path> frames;
  for (int k = 0; k < n; ++k) frames.push_back(writer.frame_path(k));
  const cv::Mat sheet = th::video::contact_sheet(frames, 6, 3, 128);
  CHECK(sheet.cols == 3 * 128 + 4 * 4);
  CHECK(sheet.rows == 2 * 128 + 3 * 4);
  cv::imwrite((dir / "contact_sheet.png").string(), sheet);
}
