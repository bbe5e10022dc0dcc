#include "bake/march.hpp"

#include <ATen/Parallel.h>
#include <torch/torch.h>

#include <algorithm>
#include <atomic>
#include <cmath>

#include "data/rays.hpp"

namespace th::bake {
namespace {

// Where a world point falls in the grid: the first of its cell's 8 lattice points inside its
// brick's arrays, and its position inside the cell.
struct Location {
  int64_t base;
  float fx, fy, fz;
};

class Grid {
 public:
  explicit Grid(const BakedFrame& f)
      : f_(f), inv_(1.0 / f.voxel), nb_(f.bricks()), P_(f.brick + 1), P3_(f.points_per_brick()) {}

  // False outside the lattice or in a brick that is not stored (density 0 there).
  bool locate(const double p[3], Location& at) const {
    // Samples on the box's faces (the first and the last of many rays) lie on the lattice's
    // edge up to rounding: within kEdge cells of it they count as on it.
    constexpr double kEdge = 1e-3;
    double u = (p[0] - f_.origin[0]) * inv_, v = (p[1] - f_.origin[1]) * inv_,
           w = (p[2] - f_.origin[2]) * inv_;
    if (!(u >= -kEdge && v >= -kEdge && w >= -kEdge && u <= f_.cells[0] + kEdge &&
          v <= f_.cells[1] + kEdge && w <= f_.cells[2] + kEdge))
      return false;
    u = std::clamp(u, 0.0, double(f_.cells[0]));
    v = std::clamp(v, 0.0, double(f_.cells[1]));
    w = std::clamp(w, 0.0, double(f_.cells[2]));
    const int64_t i = std::min<int64_t>(int64_t(u), f_.cells[0] - 1),
                  j = std::min<int64_t>(int64_t(v), f_.cells[1] - 1),
                  k = std::min<int64_t>(int64_t(w), f_.cells[2] - 1);
    const int64_t B = f_.brick, bi = i / B, bj = j / B, bk = k / B;
    const int32_t s = f_.slot[size_t((bi * nb_[1] + bj) * nb_[2] + bk)];
    if (s < 0) return false;
    at.base = s * P3_ + ((i - bi * B) * P_ + (j - bj * B)) * P_ + (k - bk * B);
    at.fx = float(u - double(i));
    at.fy = float(v - double(j));
    at.fz = float(w - double(k));
    return true;
  }

  // The 8 lattice points of `at`'s cell and their trilinear weights.
  struct Corners {
    int64_t point[8];
    float weight[8];
  };
  Corners corners(const Location& at) const {
    const int64_t dx = P_ * P_, dy = P_;
    const float wx[2] = {1 - at.fx, at.fx}, wy[2] = {1 - at.fy, at.fy}, wz[2] = {1 - at.fz, at.fz};
    Corners c{};
    for (int a = 0, i = 0; a < 2; ++a)
      for (int b = 0; b < 2; ++b)
        for (int k = 0; k < 2; ++k, ++i) {
          c.point[i] = at.base + a * dx + b * dy + k;
          c.weight[i] = wx[a] * wy[b] * wz[k];
        }
    return c;
  }

  // Trilinear interpolation of the density.
  float density(const Corners& c) const {
    float out = 0;
    for (int i = 0; i < 8; ++i) out += c.weight[i] * f_.density[size_t(c.point[i])];
    return out;
  }

  // The colour: the corners' colours (`dims` floats at `data` of each lattice point, `stride` per
  // point) weighted by their trilinear weights times their positive density, as compositing
  // weighs them; corners outside the body (density <= 0) have no say. Into out[dims]; black when
  // no corner has positive density.
  void color(const Corners& c, const float* data, int stride, int dims, float* out) const {
    float total = 0;
    for (int d = 0; d < dims; ++d) out[d] = 0;
    for (int i = 0; i < 8; ++i) {
      const float w = c.weight[i] * std::max(f_.density[size_t(c.point[i])], 0.0f);
      if (!(w > 0)) continue;
      total += w;
      const float* v = data + c.point[i] * stride;
      for (int d = 0; d < dims; ++d) out[d] += w * v[d];
    }
    if (total > 0)
      for (int d = 0; d < dims; ++d) out[d] /= total;
  }

 private:
  const BakedFrame& f_;
  double inv_;
  std::array<int64_t, 3> nb_;
  int64_t P_, P3_;
};

}  // namespace

BakedImages render_baked(const BakedFrame& frame, const torch::Tensor& K, const torch::Tensor& R,
                         const torch::Tensor& T, int width, int height,
                         const MarchOptions& options) {
  return *render_baked(frame, K, R, T, width, height, options, {});
}

std::optional<BakedImages> render_baked(const BakedFrame& frame, const torch::Tensor& K,
                                        const torch::Tensor& R, const torch::Tensor& T, int width,
                                        int height, const MarchOptions& options,
                                        const std::function<bool()>& cancelled) {
  TORCH_CHECK(options.samples >= 2, "render_baked: at least 2 samples per ray, got ",
              options.samples);
  TORCH_CHECK(width > 0 && height > 0, "render_baked: empty image ", width, "x", height);
  TORCH_CHECK(options.color_set >= 0 && options.color_set < frame.color_sets(),
              "render_baked: colour set ", options.color_set, " of a bake with ",
              frame.color_sets());
  const auto Kinv = torch::inverse(K.to(torch::kFloat64)).contiguous();
  const auto Rm = R.to(torch::kFloat64).contiguous();
  const auto origin = -torch::mv(Rm.t(), T.to(torch::kFloat64).reshape({3})).contiguous();
  // d = R^T K^-1 [x, y, 1]^T = A [x, y, 1]^T
  const auto A = torch::mm(Rm.t(), Kinv).contiguous();
  const double* a = A.data_ptr<double>();
  const double o[3] = {origin[0].item<double>(), origin[1].item<double>(),
                       origin[2].item<double>()};

  BakedImages out;
  out.rgb = torch::zeros({height, width, 3}, torch::kFloat32);
  out.depth = torch::zeros({height, width}, torch::kFloat32);
  out.acc = torch::zeros({height, width}, torch::kFloat32);
  float* rgb = out.rgb.data_ptr<float>();
  float* depth = out.depth.data_ptr<float>();
  float* acc = out.acc.data_ptr<float>();
  const Grid grid(frame);
  const int S = options.samples;
  const int color_stride = kColorDims * frame.color_sets();
  const float* color = frame.color.data() + kColorDims * options.color_set;
  const double tau = options.termination;
  std::atomic<int64_t> rays{0}, samples{0}, occupied{0}, terminated{0};

  // Bands of rows of about kBandSamples samples per thread (a ray's samples at most), so that a
  // band takes milliseconds whatever the image size and samples.
  constexpr int64_t kBandSamples = int64_t{1} << 18;
  const int64_t band =
      std::max<int64_t>(1, kBandSamples / (int64_t(width) * S)) * at::get_num_threads();
  const auto march_rows = [&](int64_t y0, int64_t y1) {
    int64_t n_rays = 0, n_samples = 0, n_occupied = 0, n_terminated = 0;
    for (int64_t y = y0; y < y1; ++y)
      for (int64_t x = 0; x < width; ++x) {
        const double d[3] = {a[0] * x + a[1] * y + a[2], a[3] * x + a[4] * y + a[5],
                             a[6] * x + a[7] * y + a[8]};
        double near = 0, far = 0;
        if (!data::near_far_ray(o, d, frame.box, near, far)) continue;
        ++n_rays;
        const double norm = std::sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
        double trans = 1, r = 0, g = 0, b = 0, z_sum = 0, w_sum = 0;
        for (int i = 0; i < S; ++i) {
          const double t = double(i) / (S - 1);
          const double z = near * (1 - t) + far * t;
          ++n_samples;
          const double p[3] = {o[0] + d[0] * z, o[1] + d[1] * z, o[2] + d[2] * z};
          Location at;
          if (!grid.locate(p, at)) continue;
          ++n_occupied;
          const auto corners = grid.corners(at);
          const float sigma = grid.density(corners);
          if (!(sigma > 0)) continue;
          const double delta =
              (i + 1 < S
                   ? (near * (1 - double(i + 1) / (S - 1)) + far * double(i + 1) / (S - 1)) - z
                   : 1e10) *
              norm;
          const double alpha = 1 - std::exp(-double(sigma) * delta);
          const double weight = alpha * trans;
          float col[kColorDims];
          grid.color(corners, color, color_stride, kColorDims, col);
          r += weight * std::clamp(col[0], 0.0f, 1.0f);
          g += weight * std::clamp(col[1], 0.0f, 1.0f);
          b += weight * std::clamp(col[2], 0.0f, 1.0f);
          z_sum += weight * z;
          w_sum += weight;
          trans *= 1 - alpha + 1e-10;
          if (tau > 0 && trans < tau) {
            ++n_terminated;
            break;
          }
        }
        const int64_t pixel = y * width + x;
        rgb[3 * pixel + 0] = float(r);
        rgb[3 * pixel + 1] = float(g);
        rgb[3 * pixel + 2] = float(b);
        depth[pixel] = float(z_sum);
        acc[pixel] = float(w_sum);
      }
    rays += n_rays;
    samples += n_samples;
    occupied += n_occupied;
    terminated += n_terminated;
  };
  for (int64_t y = 0; y < height; y += band) {
    if (cancelled && cancelled()) return std::nullopt;
    at::parallel_for(y, std::min<int64_t>(height, y + band), 1, march_rows);
  }
  out.stats = {rays.load(), samples.load(), occupied.load(), terminated.load()};
  return out;
}

}  // namespace th::bake
