// Camera path files (YAML or JSON) and single cameras by index.

#include <torch/torch.h>

#include <catch2/catch.hpp>
#include <fstream>

#include "core/error.hpp"
#include "geometry/camera.hpp"
#include "support/test_env.hpp"
#include "video/camera_path.hpp"

using th::video::CameraPath;
using th::video::PathCamera;

namespace {

PathCamera camera(double angle) {
  auto eye = torch::tensor({3 * std::cos(angle), 3 * std::sin(angle), 1.4}, torch::kFloat64);
  auto [R, T] = th::geometry::look_at(eye, torch::tensor({0.0, 0.0, 1.0}, torch::kFloat64),
                                      torch::tensor({0.0, 0.0, 1.0}, torch::kFloat64));
  auto K =
      torch::tensor({{500.0, 0.0, 255.5}, {0.0, 501.0, 256.5}, {0.0, 0.0, 1.0}}, torch::kFloat64);
  return {K, R, T};
}

void write_text(const std::filesystem::path& p, const std::string& text) {
  std::ofstream(p) << text;
}

const char* kIdentity = "R: [[1, 0, 0], [0, 1, 0], [0, 0, 1]]";
const char* kK = "K: [500, 0, 256, 0, 500, 256, 0, 0, 1]";

}  // namespace

TEST_CASE("camera path files round-trip exactly", "[video][camera_path]") {
  const auto dir = th::test::scratch_dir("video_camera_path");
  CameraPath path;
  path.width = 512;
  path.height = 384;
  for (int k = 0; k < 5; ++k) path.cameras.push_back(camera(0.7 * k + 0.123456789));
  th::video::write_camera_path(dir / "orbit.yaml", path);
  const auto back = th::video::read_camera_path(dir / "orbit.yaml");
  CHECK(back.width == 512);
  CHECK(back.height == 384);
  REQUIRE(back.cameras.size() == 5);
  for (size_t k = 0; k < 5; ++k) {
    CHECK(torch::equal(back.cameras[k].K, path.cameras[k].K));
    CHECK(torch::equal(back.cameras[k].R, path.cameras[k].R));
    CHECK(torch::equal(back.cameras[k].T, path.cameras[k].T));
  }
}

TEST_CASE("camera path files in JSON, flat and nested matrices", "[video][camera_path]") {
  const auto dir = th::test::scratch_dir("video_camera_path_json");
  write_text(dir / "path.json",
             R"({"cameras": [{"K": [[500, 0, 256], [0, 500, 256], [0, 0, 1]],
                              "R": [1, 0, 0, 0, 1, 0, 0, 0, 1], "T": [0.1, 0.2, 3]},
                             {"K": [500, 0, 256, 0, 500, 256, 0, 0, 1],
                              "R": [[0, -1, 0], [1, 0, 0], [0, 0, 1]], "T": [[0], [0], [2]]}]})");
  const auto path = th::video::read_camera_path(dir / "path.json");
  REQUIRE(path.cameras.size() == 2);
  CHECK(path.width == 0);
  CHECK(torch::equal(path.cameras[0].T,
                     torch::tensor({0.1, 0.2, 3.0}, torch::kFloat64).reshape({3, 1})));
  CHECK(path.cameras[1].R[0][1].item<double>() == -1.0);
  CHECK(path.cameras[1].K[1][2].item<double>() == 256.0);
}

TEST_CASE("camera path files: errors name the file, the camera and the key",
          "[video][camera_path]") {
  const auto dir = th::test::scratch_dir("video_camera_path_errors");
  const auto p = dir / "bad.yaml";
  auto expect = [&](const std::string& text, const std::string& needle) {
    write_text(p, text);
    INFO(text);
    CHECK_THROWS_WITH(th::video::read_camera_path(p),
                      Catch::Contains("bad.yaml") && Catch::Contains(needle));
  };
  expect("cameras: []", "non-empty");
  expect("frames: 3", "cameras");
  expect(std::string("cameras:\n  - {") + kK + ", " + kIdentity + "}", "cameras[0].T");
  expect(std::string("cameras:\n  - {") + kK + ", " + kIdentity + ", T: [1, 2, 3]}\n  - {" + kK +
             ", R: [[1, 0, 0], [0, 2, 0], [0, 0, 1]], T: [1, 2, 3]}",
         "cameras[1].R: not a rotation");
  expect(std::string("cameras:\n  - {") + kK + ", " + kIdentity + ", T: [1, 2]}",
         "cameras[0].T: expected 3x1");
  expect(std::string("cameras:\n  - {K: [1, 0, 0, 0, 1, 0, 0, 0, 2], ") + kIdentity +
             ", T: [1, 2, 3]}",
         "cameras[0].K");
  expect(std::string("cameras:\n  - {") + kK + ", " + kIdentity + ", T: [1, x, 3]}",
         "cameras[0].T: not a list of numbers");
  expect("cameras: [", "cannot parse");
  CHECK_THROWS_WITH(th::video::read_camera_path(dir / "missing.yaml"),
                    Catch::Contains("missing.yaml") && Catch::Contains("does not exist"));
}

TEST_CASE("a single camera by index, with the valid range in the error", "[video][camera_path]") {
  std::vector<PathCamera> cams = {camera(0), camera(1), camera(2)};
  const auto one = th::video::single_camera(cams, 2, "CoreView_387 cameras");
  REQUIRE(one.cameras.size() == 1);
  CHECK(torch::equal(one.cameras[0].R, cams[2].R));
  CHECK_THROWS_WITH(th::video::single_camera(cams, 3, "CoreView_387 cameras"),
                    Catch::Contains("camera index 3") && Catch::Contains("CoreView_387") &&
                        Catch::Contains("0..2"));
  CHECK_THROWS_AS(th::video::single_camera(cams, -1), th::Error);
}
