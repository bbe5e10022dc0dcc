#include "video/camera_path.hpp"

#include <torch/torch.h>
#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cmath>
#include <sstream>

#include "core/error.hpp"
#include "core/files.hpp"
#include "geometry/camera.hpp"
#include "io/files.hpp"

namespace th::video {
namespace {

torch::Tensor f64(const torch::Tensor& t) { return t.to(torch::kFloat64).cpu(); }

torch::Tensor unit(const torch::Tensor& v) { return v / v.norm(); }

// numpy.percentile(values, q) with its default 'linear' method: values (C) -> scalar.
double percentile(torch::Tensor values, double q) {
  auto sorted = std::get<0>(values.to(torch::kFloat64).sort());
  const int64_t n = sorted.numel();
  const double h = (n - 1) * q / 100.0;
  const auto lo = static_cast<int64_t>(std::floor(h));
  const int64_t hi = std::min(lo + 1, n - 1);
  const double a = sorted[lo].item<double>(), b = sorted[hi].item<double>();
  return a + (h - double(lo)) * (b - a);
}

}  // namespace

Orbit make_orbit(const torch::Tensor& R, const torch::Tensor& T) {
  TORCH_CHECK(R.dim() == 3 && R.size(1) == 3 && R.size(2) == 3 && R.size(0) >= 1,
              "make_orbit: R must be (C, 3, 3), got ", R.sizes());
  TORCH_CHECK(T.size(0) == R.size(0) && T.numel() == 3 * R.size(0),
              "make_orbit: T must be (C, 3, 1) or (C, 3) with C = ", R.size(0), ", got ",
              T.sizes());
  auto r = f64(R);
  auto t = f64(T).reshape({-1, 3, 1});
  // Camera centres -R^T T: (C, 3).
  auto centres = -torch::matmul(r.transpose(1, 2), t).squeeze(2);

  Orbit orbit;
  orbit.center = centres.mean(0);
  // METHOD 7's up: the reference's LLFF x axis = OpenCV's y axis = row 1 of R.
  auto up_sum = r.select(1, 1).sum(0);
  if (up_sum.norm().item<double>() < 1e-9)
    fail("orbit: the cameras' y axes cancel out, no up direction for the orbit");
  orbit.up = unit(up_sum);
  // The reference's z: camera 0's LLFF "backwards" axis, -(row 2 of R[0]).
  auto z0 = -r[0][2];
  auto a1 = torch::cross(z0, orbit.up, 0);
  if (a1.norm().item<double>() < 1e-9)
    fail("orbit: camera 0 looks along the up direction, the orbit plane is undefined");
  a1 = unit(a1);
  auto a2 = unit(torch::cross(orbit.up, a1, 0));
  orbit.axes = torch::stack({orbit.up, a1, a2}, 0);
  // Centres in that basis (the reference's ptstocam), then 1.3 x the 80th percentile per axis.
  auto local = torch::matmul(centres - orbit.center, orbit.axes.t()).abs();  // (C, 3)
  orbit.radii = torch::empty({3}, torch::kFloat64);
  for (int a = 0; a < 3; ++a) orbit.radii[a] = 1.3 * percentile(local.select(1, a), 80.0);
  return orbit;
}

PathCamera orbit_camera(const Orbit& orbit, const torch::Tensor& K, const torch::Tensor& target,
                        double theta) {
  TORCH_CHECK(K.dim() == 2 && K.size(0) == 3 && K.size(1) == 3,
              "orbit_camera: K must be (3, 3), got ", K.sizes());
  TORCH_CHECK(target.numel() == 3, "orbit_camera: target must hold 3 values, got ", target.sizes());
  auto eye = orbit.center + orbit.radii[1] * std::sin(theta) * orbit.axes[1] +
             orbit.radii[2] * std::cos(theta) * orbit.axes[2];
  // The reference's viewmatrix(z = unit(eye - target), up, eye) gives LLFF columns
  // [v0, v1, v2] = [unit(v1 x v2), unit(z x up), z] and reorders them to OpenCV's
  // [x, y, z] = [v1, v0, -v2]. With f = -z (forward): x = unit(-f x up) = unit(f x (-up)),
  // y = v1 x v2 = x x (-f) = f x x. look_at(eye, target, -up) computes x = unit(f x (-up)),
  // y = f x x: the same camera.
  auto [R, T] = geometry::look_at(eye, f64(target).reshape({3}), -orbit.up);
  return {f64(K).clone(), R, T};
}

std::vector<PathCamera> orbit_path(const Orbit& orbit, const torch::Tensor& K,
                                   const torch::Tensor& target, int n) {
  TORCH_CHECK(n >= 1, "orbit_path: n must be >= 1, got ", n);
  std::vector<PathCamera> path;
  path.reserve(n);
  for (int k = 0; k < n; ++k) path.push_back(orbit_camera(orbit, K, target, 2.0 * M_PI * k / n));
  return path;
}

// ---- path files ------------------------------------------------------------------------------

namespace {

// A (rows, cols) matrix from a nested sequence [[..], ..] or a flat one of rows*cols numbers.
torch::Tensor read_matrix(const YAML::Node& node, int rows, int cols, const std::string& where) {
  std::vector<double> values;
  try {
    if (!node || !node.IsSequence()) fail(where, " is missing or not a list");
    for (const auto& item : node) {
      if (item.IsSequence()) {
        if (static_cast<int>(item.size()) != cols)
          fail(where, ": each row must hold ", cols, " numbers");
        for (const auto& x : item) values.push_back(x.as<double>());
      } else {
        values.push_back(item.as<double>());
      }
    }
  } catch (const YAML::Exception& e) {
    fail(where, ": not a list of numbers (", e.msg, ")");
  }
  if (static_cast<int>(values.size()) != rows * cols)
    fail(where, ": expected ", rows, "x", cols, " numbers, got ", values.size());
  for (double v : values)
    if (!std::isfinite(v)) fail(where, ": holds a non-finite number");
  return torch::tensor(values, torch::kFloat64).reshape({rows, cols});
}

YAML::Node matrix_node(const torch::Tensor& m) {
  auto c = m.to(torch::kFloat64).contiguous();
  YAML::Node rows(YAML::NodeType::Sequence);
  for (int64_t i = 0; i < c.size(0); ++i) {
    YAML::Node row(YAML::NodeType::Sequence);
    row.SetStyle(YAML::EmitterStyle::Flow);
    for (int64_t j = 0; j < c.size(1); ++j) row.push_back(c[i][j].item<double>());
    rows.push_back(row);
  }
  rows.SetStyle(YAML::EmitterStyle::Flow);
  return rows;
}

}  // namespace

CameraPath read_camera_path(const std::filesystem::path& path) {
  const std::string name = path.string();
  if (!std::filesystem::exists(path)) fail("camera path file '", name, "' does not exist");
  refuse_special_file(path, "camera path file");
  // Bounded before parsing: about 300 bytes per camera, so 32 MiB is some 100,000 cameras.
  constexpr uintmax_t kMaxBytes = uintmax_t{32} << 20;
  if (const auto bytes = std::filesystem::file_size(path); bytes > kMaxBytes)
    fail("camera path file '", name, "' is ", bytes, " bytes, more than a camera path may be (",
         kMaxBytes, ")");
  YAML::Node root;
  try {
    root = YAML::LoadFile(name);
  } catch (const YAML::Exception& e) {
    fail("cannot parse camera path file '", name, "': ", e.what());
  }
  if (!root.IsMap()) fail("camera path file '", name, "': expected a map with key 'cameras'");
  CameraPath out;
  for (const char* key : {"width", "height"}) {
    if (!root[key]) continue;
    int v = 0;
    try {
      v = root[key].as<int>();
    } catch (const YAML::Exception&) {
      fail("camera path file '", name, "': '", key, "' must be an integer");
    }
    if (v < 0) fail("camera path file '", name, "': '", key, "' must be >= 0, got ", v);
    (std::string(key) == "width" ? out.width : out.height) = v;
  }
  const YAML::Node cams = root["cameras"];
  if (!cams || !cams.IsSequence() || cams.size() == 0)
    fail("camera path file '", name, "': 'cameras' must be a non-empty list");
  constexpr size_t kMaxCameras = 108000;  // inference::kMaxVideoFrames: an hour at 30 fps
  if (cams.size() > kMaxCameras)
    fail("camera path file '", name, "': ", cams.size(), " cameras, more than a video may have (",
         kMaxCameras, ")");
  for (size_t i = 0; i < cams.size(); ++i) {
    const std::string where = "camera path file '" + name + "': cameras[" + std::to_string(i) + "]";
    if (!cams[i].IsMap()) fail(where, " must be a map with K, R, T");
    PathCamera c;
    c.K = read_matrix(cams[i]["K"], 3, 3, where + ".K");
    c.R = read_matrix(cams[i]["R"], 3, 3, where + ".R");
    c.T = read_matrix(cams[i]["T"], 3, 1, where + ".T");
    const double fx = c.K[0][0].item<double>(), fy = c.K[1][1].item<double>();
    if (!(fx > 0 && fy > 0)) fail(where, ".K: focal lengths must be > 0, got ", fx, ", ", fy);
    if (!torch::allclose(c.K[2], torch::tensor({0.0, 0.0, 1.0}, torch::kFloat64)))
      fail(where, ".K: last row must be [0, 0, 1]");
    const double ortho =
        (torch::matmul(c.R, c.R.t()) - torch::eye(3, torch::kFloat64)).abs().max().item<double>();
    const double det = torch::det(c.R).item<double>();
    if (ortho > 1e-4 || std::abs(det - 1.0) > 1e-4)
      fail(where, ".R: not a rotation (|R R^T - I| = ", ortho, ", det = ", det, ")");
    out.cameras.push_back(c);
  }
  return out;
}

void write_camera_path(const std::filesystem::path& path, const CameraPath& cameras) {
  YAML::Node root(YAML::NodeType::Map);
  if (cameras.width > 0) root["width"] = cameras.width;
  if (cameras.height > 0) root["height"] = cameras.height;
  YAML::Node list(YAML::NodeType::Sequence);
  for (const PathCamera& c : cameras.cameras) {
    YAML::Node cam(YAML::NodeType::Map);
    cam["K"] = matrix_node(c.K);
    cam["R"] = matrix_node(c.R);
    auto t = matrix_node(c.T.reshape({1, 3}))[0];
    cam["T"] = t;
    list.push_back(cam);
  }
  root["cameras"] = list;
  YAML::Emitter emitter;
  emitter.SetDoublePrecision(17);  // round-trips float64 exactly
  emitter << root;
  std::string text = "# x_cam = R x_world + T (METHOD 2.2); T in metres; one camera per frame\n";
  text += emitter.c_str();
  text += "\n";
  io::write_file_atomic(path, text);
}

CameraPath single_camera(const std::vector<PathCamera>& cameras, int index,
                         const std::string& what) {
  if (index < 0 || index >= static_cast<int>(cameras.size()))
    fail("camera index ", index, " out of range: ", what, " has ", cameras.size(), " cameras (0..",
         static_cast<int>(cameras.size()) - 1, ")");
  CameraPath path;
  path.cameras.push_back(cameras[index]);
  return path;
}

}  // namespace th::video
