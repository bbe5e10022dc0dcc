#pragma once
// A small synthetic frame for model and renderer tests: an ellipsoidal "body" of a few hundred
// vertices, Voronoi clusters as tokens, three cameras around it and random reference images.

#include <torch/torch.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>
#include <string>
#include <vector>

#include "core/config.hpp"
#include "model/inputs.hpp"
#include "render/volume.hpp"
#include "support/test_env.hpp"

namespace th::test {

// The largest absolute difference of two tensors of one shape.
inline double max_abs(const torch::Tensor& a, const torch::Tensor& b) {
  return (a - b).abs().max().item<double>();
}

// grid_sample(bilinear, border, align_corners=true) of maps at pixel coordinates, with the
// reference's normalisation u * 2 / (W - 1) - 1. map: (V, C, H, W), uv: (N, V, 2) -> (N, V, C).
inline torch::Tensor grid_sample_pixels(const torch::Tensor& map, const torch::Tensor& uv) {
  namespace F = torch::nn::functional;
  const auto H = map.size(2), W = map.size(3);
  const auto scale = torch::tensor({2.0 / (W - 1), 2.0 / (H - 1)}, uv.options());
  const auto grid = (uv * scale - 1).permute({1, 0, 2}).unsqueeze(1);  // (V, 1, N, 2)
  return F::grid_sample(map, grid,
                        F::GridSampleFuncOptions()
                            .mode(torch::kBilinear)
                            .padding_mode(torch::kBorder)
                            .align_corners(true))
      .squeeze(2)
      .permute({2, 0, 1});
}

// p_v at full resolution: the levels upsampled to the images' size (bilinear, align_corners) and
// the raw-RGB convolution `color` (undefined w/o RGB), (V, 384, H, W).
inline torch::Tensor pixel_feature_map(const std::vector<torch::Tensor>& levels,
                                       const torch::Tensor& images,
                                       const torch::nn::Conv2d& color) {
  namespace F = torch::nn::functional;
  const auto up = F::InterpolateFuncOptions()
                      .size(std::vector<int64_t>{images.size(2), images.size(3)})
                      .mode(torch::kBilinear)
                      .align_corners(true);
  std::vector<torch::Tensor> p;
  for (const auto& level : levels) p.push_back(F::interpolate(level, up));
  if (color) p.push_back(torch::conv2d(images, color->weight, color->bias));
  return torch::cat(p, 1);
}

inline torch::Tensor rotation_y(double a) {
  return torch::tensor(
             {std::cos(a), 0.0, std::sin(a), 0.0, 1.0, 0.0, -std::sin(a), 0.0, std::cos(a)},
             torch::kDouble)
      .view({3, 3});
}

inline torch::Tensor rotation_x(double a) {
  return torch::tensor(
             {1.0, 0.0, 0.0, 0.0, std::cos(a), -std::sin(a), 0.0, std::sin(a), std::cos(a)},
             torch::kDouble)
      .view({3, 3});
}

struct SyntheticFrame {
  model::FrameInputs inputs;
  torch::Tensor target_K, target_R, target_T;  // a fourth camera for rendering
  int64_t size = 32;
};

// nv vertices, nt tokens, V reference views of size x size pixels.
inline SyntheticFrame synthetic_frame(int64_t nv = 300, int64_t nt = 24, int64_t V = 3,
                                      int64_t size = 32, uint64_t seed = 0) {
  torch::manual_seed(seed);
  SyntheticFrame f;
  f.size = size;
  auto& in = f.inputs;
  // Canonical body: points on an ellipsoid (SMPL frame, metres), float64 like v_template.
  auto dir = torch::randn({nv, 3}, torch::kDouble);
  dir = dir / dir.norm(2, 1, true);
  const auto canonical = dir * torch::tensor({0.25, 0.7, 0.15}, torch::kDouble);
  in.canonical = canonical;
  // Posed: a small deformation; A: rotations near identity, blended (not orthonormal).
  const auto xs = canonical + 0.02 * torch::randn({nv, 3}, torch::kDouble);
  in.A = (torch::eye(3, torch::kDouble).expand({nv, 3, 3}) +
          0.1 * torch::randn({nv, 3, 3}, torch::kDouble))
             .to(torch::kFloat);
  const auto Rh = torch::mm(rotation_y(0.3), rotation_x(0.1));
  const auto Th = torch::tensor({0.1, -0.05, 0.2}, torch::kDouble);
  in.Rh = Rh.to(torch::kFloat);
  in.Th = Th.to(torch::kFloat);
  in.vertices = (torch::mm(xs, Rh.t()) + Th).to(torch::kFloat);
  // Voronoi clusters of nt seed vertices (every cluster non-empty).
  const auto seeds = canonical.narrow(0, 0, nt);
  in.labels = std::get<1>(torch::cdist(canonical, seeds).min(1));
  in.num_tokens = nt;
  // Cameras on a circle of radius 3 m around the body, looking at it.
  const double focal = size * 1.4;
  auto K =
      torch::tensor({focal, 0.0, size / 2.0, 0.0, focal, size / 2.0, 0.0, 0.0, 1.0}, torch::kDouble)
          .view({3, 3});
  std::vector<torch::Tensor> Ks, Rs, Ts;
  for (int64_t v = 0; v <= V; ++v) {
    const auto R = rotation_y(2 * M_PI * v / (V + 1) + 0.2);
    const auto T = torch::tensor({0.0, 0.0, 3.0}, torch::kDouble) - torch::mv(R, Th);
    Ks.push_back(K);
    Rs.push_back(R);
    Ts.push_back(T.view({3, 1}));
  }
  in.K = torch::stack(std::vector<torch::Tensor>(Ks.begin(), Ks.begin() + V)).to(torch::kFloat);
  in.R = torch::stack(std::vector<torch::Tensor>(Rs.begin(), Rs.begin() + V)).to(torch::kFloat);
  in.T = torch::stack(std::vector<torch::Tensor>(Ts.begin(), Ts.begin() + V)).to(torch::kFloat);
  f.target_K = Ks[V].to(torch::kFloat);
  f.target_R = Rs[V].to(torch::kFloat);
  f.target_T = Ts[V].to(torch::kFloat);
  in.ref_images = torch::rand({V, 3, size, size});
  in.visibility = torch::rand({V, nv}) < 0.8;
  return f;
}

// Rays of the target camera through the pixels of an s x s image that meet the body's box
// (padded by 0.1 m); near/far from the slab intersection.
inline render::Rays target_rays(const SyntheticFrame& f, int64_t s) {
  const auto K = f.target_K.to(torch::kDouble), R = f.target_R.to(torch::kDouble),
             T = f.target_T.to(torch::kDouble);
  const auto scale = static_cast<double>(s) / f.size;
  auto Ks = K.clone();
  Ks.narrow(0, 0, 2).mul_(scale);
  const auto o = -torch::mv(R.t(), T.flatten());
  const auto ys = torch::arange(s, torch::kDouble), xs = torch::arange(s, torch::kDouble);
  const auto grid = torch::meshgrid({ys, xs}, "ij");
  const auto pix =
      torch::stack({grid[1].flatten(), grid[0].flatten(), torch::ones({s * s}, torch::kDouble)}, 1);
  const auto d = torch::mm(torch::mm(pix, torch::inverse(Ks).t()), R);  // R^T K^-1 [x y 1]
  const auto v = f.inputs.vertices.to(torch::kDouble);
  const auto lo = std::get<0>(v.min(0)) - 0.1, hi = std::get<0>(v.max(0)) + 0.1;
  const auto dd = torch::where(d.abs() < 1e-5, torch::full_like(d, 1e-5), d);
  const auto t0 = (lo - o) / dd, t1 = (hi - o) / dd;
  const auto tmin = std::get<0>(torch::minimum(t0, t1).max(1));
  const auto tmax = std::get<0>(torch::maximum(t0, t1).min(1));
  const auto valid = (tmax > tmin) & (tmin > 0);
  const auto idx = valid.nonzero().flatten();
  const auto dtype = f.inputs.vertices.scalar_type();
  render::Rays r;
  r.directions = d.index_select(0, idx).to(dtype);
  r.origins = o.unsqueeze(0).expand({idx.size(0), 3}).contiguous().to(dtype);
  r.near = tmin.index_select(0, idx).to(dtype);
  r.far = tmax.index_select(0, idx).to(dtype);
  return r;
}

// Shifts the density head's bias so that about half of the points near the body have
// sigma_raw > 0 (a freshly initialised head may output sigma <= 0 everywhere, which would make
// every gradient of a rendering loss zero).
// `gain` then scales the head (larger densities, opaque surfaces).
template <class Model>
void center_density(Model& model, const SyntheticFrame& f, double gain = 1.0) {
  torch::NoGradGuard no_grad;
  const auto cache = model.prepare(f.inputs, 0.1);
  const auto& v = f.inputs.vertices;
  const auto pts = v + 0.03 * torch::randn(v.sizes(), v.options());
  const auto raw = model.forward(cache, pts, torch::randn(v.sizes(), v.options()));
  model.heads->alpha_fc->bias.sub_(raw.select(1, 3).median());
  model.heads->alpha_fc->bias.mul_(gain);
  model.heads->alpha_fc->weight.mul_(gain);
}

// A small model configuration for tests: everything as the default except sizes.
inline ModelConfig tiny_model_config(int depth = 2) {
  ModelConfig c;
  c.transhe.depth = depth;
  c.grouping.num_tokens = 24;
  return c;
}

// Raw little-endian arrays exchanged with the Python reference scripts.
inline void write_raw(const std::string& path, const torch::Tensor& t) {
  const auto c = t.contiguous().cpu();
  std::ofstream f(path, std::ios::binary);
  f.write(static_cast<const char*>(c.data_ptr()), c.numel() * c.element_size());
}

inline torch::Tensor read_raw(const std::string& path, torch::IntArrayRef shape,
                              torch::ScalarType dtype) {
  auto t = torch::empty(shape, dtype);
  std::ifstream f(path, std::ios::binary);
  f.read(static_cast<char*>(t.data_ptr()), t.numel() * t.element_size());
  if (!f) throw std::runtime_error("cannot read " + path);
  return t;
}

// Tensors handed to tests/python/model_reference.py and its answers.
class PythonReference {
 public:
  explicit PythonReference(const std::string& name) : dir_(scratch_dir(name)) {}
  const std::filesystem::path& dir() const { return dir_; }

  void add(const std::string& name, const torch::Tensor& t) {
    const auto c = t.detach().cpu().contiguous();
    const char* dt = c.scalar_type() == torch::kFloat    ? "f32"
                     : c.scalar_type() == torch::kDouble ? "f64"
                                                         : "i64";
    TORCH_CHECK(c.scalar_type() == torch::kFloat || c.scalar_type() == torch::kDouble ||
                    c.scalar_type() == torch::kLong,
                "unsupported dtype for ", name);
    write_raw((dir_ / (name + ".bin")).string(), c);
    manifest_ += name + " " + dt;
    for (auto s : c.sizes()) manifest_ += " " + std::to_string(s);
    manifest_ += "\n";
  }

  // Runs the command; returns the outputs by name.
  std::map<std::string, torch::Tensor> run(const std::string& command) {
    run_all(command, {this});
    return outputs();
  }
  // Runs the command once over several inputs' folders (one Python process); each reads its
  // outputs with outputs().
  static void run_all(const std::string& command, const std::vector<PythonReference*>& refs) {
    std::string dirs;
    for (auto* r : refs) {
      std::ofstream((r->dir_ / "manifest.txt").string()) << r->manifest_;
      dirs += " " + r->dir_.string();
    }
    const int rc = run_python("tests/python/model_reference.py", command + dirs);
    if (rc != 0) throw std::runtime_error("model_reference.py " + command + " failed");
  }
  std::map<std::string, torch::Tensor> outputs() const {
    std::map<std::string, torch::Tensor> out;
    std::ifstream m((dir_ / "out_manifest.txt").string());
    std::string line;
    while (std::getline(m, line)) {
      std::istringstream in(line);
      std::string name, dt;
      in >> name >> dt;
      std::vector<int64_t> shape;
      for (int64_t s; in >> s;) shape.push_back(s);
      const auto type = dt == "f32" ? torch::kFloat : dt == "f64" ? torch::kDouble : torch::kLong;
      out[name] = read_raw((dir_ / ("out_" + name + ".bin")).string(), shape, type);
    }
    return out;
  }

 private:
  std::filesystem::path dir_;
  std::string manifest_;
};

}  // namespace th::test
