#include "data/rays.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <opencv2/imgproc.hpp>

#include "core/error.hpp"
#include "geometry/camera.hpp"

namespace th::data {
namespace {

torch::Tensor f64(const torch::Tensor& t) { return t.to(torch::kFloat64).contiguous(); }

}  // namespace

torch::Tensor bounds_of(const torch::Tensor& vertices, double pad_z) {
  TORCH_CHECK(vertices.dim() == 2 && vertices.size(1) == 3, "vertices must be (V, 3)");
  const auto v = f64(vertices);
  auto box = torch::stack({std::get<0>(v.min(0)), std::get<0>(v.max(0))});
  box.index_put_({0, 2}, box.index({0, 2}) - pad_z);
  box.index_put_({1, 2}, box.index({1, 2}) + pad_z);
  return box;
}

torch::Tensor pixel_grid(int width, int height) {
  auto ys = torch::arange(height, torch::kInt64);
  auto xs = torch::arange(width, torch::kInt64);
  auto grid = torch::meshgrid({ys, xs}, "ij");
  return torch::stack({grid[1].reshape(-1), grid[0].reshape(-1)}, 1);
}

RayBundle pixel_rays(const torch::Tensor& pixels, const torch::Tensor& K, const torch::Tensor& R,
                     const torch::Tensor& T) {
  TORCH_CHECK(pixels.dim() == 2 && pixels.size(1) == 2, "pixels must be (N, 2)");
  const auto Rm = f64(R);
  const auto xy1 = torch::cat({f64(pixels), torch::ones({pixels.size(0), 1}, torch::kFloat64)}, 1);
  // d = R^T K^-1 p, as row vectors: p^T K^-T R.
  const auto dirs = xy1.matmul(torch::inverse(f64(K)).t()).matmul(Rm);
  const auto origin = geometry::camera_center(Rm, f64(T).reshape({3}));
  return {origin.reshape({1, 3}).expand({pixels.size(0), 3}).contiguous(), dirs};
}

bool near_far_ray(const double o[3], const double d_in[3], const std::array<double, 6>& box,
                  double& near, double& far) {
  double d[3], lo[3], hi[3];
  for (int a = 0; a < 3; ++a) {
    d[a] = std::abs(d_in[a]) < 1e-5 ? 1e-5 : d_in[a];  // tiny components, of either sign
    lo[a] = box[a] - 0.01;
    hi[a] = box[3 + a] + 0.01;
  }
  const double norm = std::sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
  constexpr double eps = 1e-6;
  int inside = 0;
  near = std::numeric_limits<double>::infinity();
  far = -near;
  // The 6 planes: min x, y, z, then max x, y, z.
  for (int plane = 0; plane < 6; ++plane) {
    const int axis = plane % 3;
    const double t = ((plane < 3 ? lo[axis] : hi[axis]) - o[axis]) / d[axis];
    double p[3], sq = 0;
    bool in = true;
    for (int a = 0; a < 3; ++a) {
      p[a] = t * d[a] + o[a];
      in = in && p[a] >= lo[a] - eps && p[a] <= hi[a] + eps;
      sq += (p[a] - o[a]) * (p[a] - o[a]);
    }
    if (!in) continue;
    ++inside;
    const double dist = std::sqrt(sq) / norm;
    near = std::min(near, dist);
    far = std::max(far, dist);
  }
  if (inside == 2) return true;
  near = far = 0;
  return false;
}

NearFar near_far(const torch::Tensor& origins, const torch::Tensor& dirs,
                 const torch::Tensor& box) {
  TORCH_CHECK(origins.dim() == 2 && origins.size(1) == 3, "origins must be (N, 3)");
  TORCH_CHECK(dirs.sizes() == origins.sizes(), "dirs must be (N, 3) like origins");
  TORCH_CHECK(box.sizes() == torch::IntArrayRef({2, 3}), "box must be (2, 3)");
  const auto o = f64(origins), d = f64(dirs), b = f64(box);
  std::array<double, 6> bounds{};
  std::copy(b.data_ptr<double>(), b.data_ptr<double>() + 6, bounds.begin());
  const int64_t n = o.size(0);
  NearFar out{torch::zeros({n}, torch::kFloat64), torch::zeros({n}, torch::kFloat64),
              torch::zeros({n}, torch::kBool)};
  const double *po = o.data_ptr<double>(), *pd = d.data_ptr<double>();
  double *near = out.near.data_ptr<double>(), *far = out.far.data_ptr<double>();
  bool* valid = out.valid.data_ptr<bool>();
  // One thread: the loader's workers call this beside the renderer's threads.
  for (int64_t i = 0; i < n; ++i)
    valid[i] = near_far_ray(po + 3 * i, pd + 3 * i, bounds, near[i], far[i]);
  return out;
}

cv::Mat box_mask(const torch::Tensor& box, const torch::Tensor& K, const torch::Tensor& R,
                 const torch::Tensor& T, int width, int height) {
  const auto b = f64(box);
  std::vector<torch::Tensor> corners;
  for (int i = 0; i < 8; ++i)  // corner i: bit 0 = x max, bit 1 = y max, bit 2 = z max
    corners.push_back(torch::stack({b[(i >> 0) & 1][0], b[(i >> 1) & 1][1], b[(i >> 2) & 1][2]}));
  const auto uv = geometry::project_points(torch::stack(corners), K, R, T);
  const auto a = uv.accessor<double, 2>();
  // The 6 faces as corner indices, each a quadrilateral in cyclic order.
  static const int faces[6][4] = {{0, 2, 6, 4}, {1, 3, 7, 5}, {0, 1, 5, 4},
                                  {2, 3, 7, 6}, {0, 1, 3, 2}, {4, 5, 7, 6}};
  cv::Mat mask = cv::Mat::zeros(height, width, CV_8U);
  for (const auto& f : faces) {
    std::vector<cv::Point> poly;
    for (int c : f) poly.emplace_back(int(a[c][0]), int(a[c][1]));
    cv::fillPoly(mask, std::vector<std::vector<cv::Point>>{poly}, cv::Scalar(1));
  }
  return mask;
}

std::vector<Patch> sample_patches(const cv::Mat& body, const cv::Mat& box, int count, int size,
                                  double body_prob, std::mt19937_64& rng) {
  TORCH_CHECK(body.size() == box.size() && body.type() == CV_8U && box.type() == CV_8U,
              "body and box masks must be CV_8U images of one size");
  std::vector<cv::Point> on_body, background;
  cv::findNonZero(body, on_body);
  cv::Mat bg = (box != 0) & (body == 0);
  cv::findNonZero(bg, background);
  if (on_body.empty() && background.empty())
    fail("cannot sample training patches: the target has no person pixels and no in-box pixels");

  std::uniform_real_distribution<double> coin(0.0, 1.0);
  std::vector<Patch> patches;
  for (int i = 0; i < count; ++i) {
    const bool want_body = coin(rng) < body_prob;
    const auto& pool = (want_body && !on_body.empty()) || background.empty() ? on_body : background;
    const cv::Point c = pool[std::uniform_int_distribution<size_t>(0, pool.size() - 1)(rng)];
    const int x0 = std::max(0, c.x - size / 2), y0 = std::max(0, c.y - size / 2);
    const int x1 = std::min(body.cols, c.x - size / 2 + size);
    const int y1 = std::min(body.rows, c.y - size / 2 + size);
    patches.push_back({x0, y0, x1 - x0, y1 - y0});
  }
  return patches;
}

}  // namespace th::data
