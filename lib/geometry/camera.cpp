#include "geometry/camera.hpp"

#include <torch/torch.h>

#include <algorithm>
#include <cmath>
#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>

namespace th::geometry {
namespace {

torch::Tensor f64(const torch::Tensor& t) { return t.to(torch::kFloat64); }

// (..., 3) -> (..., 3, 3) cross-product matrices [v]x.
torch::Tensor skew(const torch::Tensor& v) {
  auto x = v.select(-1, 0), y = v.select(-1, 1), z = v.select(-1, 2);
  auto o = torch::zeros_like(x);
  return torch::stack(
      {torch::stack({o, -z, y}, -1), torch::stack({z, o, -x}, -1), torch::stack({-y, x, o}, -1)},
      -2);
}

void check_points(const torch::Tensor& t, int64_t cols, const char* name) {
  TORCH_CHECK(t.dim() == 2 && t.size(1) == cols, name, " must be (N, ", cols, "), got ", t.sizes());
}

// Distortion coefficients as five doubles (missing trailing ones are 0, as in OpenCV).
struct Coeffs {
  double k1 = 0, k2 = 0, p1 = 0, p2 = 0, k3 = 0;
};
Coeffs coeffs(const torch::Tensor& D) {
  auto d = f64(D).reshape({-1}).cpu().contiguous();
  TORCH_CHECK(d.numel() == 4 || d.numel() == 5, "D must hold 4 or 5 coefficients, got ", D.sizes());
  const double* p = d.data_ptr<double>();
  Coeffs c{p[0], p[1], p[2], p[3], d.numel() == 5 ? p[4] : 0.0};
  return c;
}

// Pixel <-> normalised coordinates with a general K (skew included).
torch::Tensor pixels_to_normalized(const torch::Tensor& uv, const torch::Tensor& K) {
  auto k = f64(K);
  auto y = (uv.select(1, 1) - k[1][2]) / k[1][1];
  auto x = (uv.select(1, 0) - k[0][2] - k[0][1] * y) / k[0][0];
  return torch::stack({x, y}, 1);
}
torch::Tensor normalized_to_pixels(const torch::Tensor& xy, const torch::Tensor& K) {
  auto k = f64(K);
  auto x = xy.select(1, 0), y = xy.select(1, 1);
  return torch::stack({k[0][0] * x + k[0][1] * y + k[0][2], k[1][1] * y + k[1][2]}, 1);
}

}  // namespace

torch::Tensor rodrigues(const torch::Tensor& rvec) {
  TORCH_CHECK(rvec.size(-1) == 3, "rodrigues: rvec must be (..., 3), got ", rvec.sizes());
  auto r = f64(rvec);
  auto theta2 = (r * r).sum(-1, true).unsqueeze(-1);  // (..., 1, 1)
  auto theta = theta2.sqrt();
  // A = sin(t)/t, B = (1 - cos(t))/t^2, with their Taylor series below 1e-4 rad where the
  // closed forms lose precision.
  auto small = theta < 1e-4;
  auto safe = torch::where(small, torch::ones_like(theta), theta);
  auto A = torch::where(small, 1.0 - theta2 / 6.0, torch::sin(safe) / safe);
  auto B = torch::where(small, 0.5 - theta2 / 24.0, (1.0 - torch::cos(safe)) / (safe * safe));
  auto Kx = skew(r);
  auto eye = torch::eye(3, r.options()).expand_as(Kx);
  return eye + A * Kx + B * torch::matmul(Kx, Kx);
}

torch::Tensor axis_angle(const torch::Tensor& R) {
  TORCH_CHECK(R.dim() >= 2 && R.size(-1) == 3 && R.size(-2) == 3,
              "axis_angle: R must be (..., 3, 3), got ", R.sizes());
  auto batch = R.sizes().slice(0, R.dim() - 2).vec();
  auto m = f64(R).reshape({-1, 3, 3}).cpu().contiguous();
  auto out = torch::empty({m.size(0), 3}, m.options());
  auto a = m.accessor<double, 3>();
  auto o = out.accessor<double, 2>();
  for (int64_t i = 0; i < m.size(0); ++i) {
    const double wx = a[i][2][1] - a[i][1][2], wy = a[i][0][2] - a[i][2][0],
                 wz = a[i][1][0] - a[i][0][1];
    const double c = std::clamp((a[i][0][0] + a[i][1][1] + a[i][2][2] - 1.0) / 2.0, -1.0, 1.0);
    const double s = 0.5 * std::sqrt(wx * wx + wy * wy + wz * wz);  // sin(theta)
    const double theta = std::atan2(s, c);
    double r[3];
    if (c > -0.99) {
      // theta / (2 sin theta) -> 1/2 + theta^2/12 as theta -> 0.
      const double f = theta < 1e-6 ? 0.5 + theta * theta / 12.0 : theta / (2.0 * s);
      r[0] = f * wx, r[1] = f * wy, r[2] = f * wz;
    } else {
      // Near pi the skew part vanishes; the symmetric part (R + R^T)/2 = c I + (1 - c) k k^T
      // gives the axis (its dominant column), the skew part only its sign.
      int col = 0;
      for (int j = 1; j < 3; ++j)
        if (a[i][j][j] > a[i][col][col]) col = j;
      double k[3];
      for (int j = 0; j < 3; ++j)
        k[j] = (0.5 * (a[i][j][col] + a[i][col][j]) - (j == col ? c : 0.0)) / (1.0 - c);
      const double n = std::sqrt(k[0] * k[0] + k[1] * k[1] + k[2] * k[2]);
      for (double& kj : k) kj /= n;
      if (k[0] * wx + k[1] * wy + k[2] * wz < 0)
        for (double& kj : k) kj = -kj;
      for (int j = 0; j < 3; ++j) r[j] = theta * k[j];
    }
    o[i][0] = r[0], o[i][1] = r[1], o[i][2] = r[2];
  }
  batch.push_back(3);
  return out.reshape(batch).to(R.device());
}

torch::Tensor world_to_camera(const torch::Tensor& points, const torch::Tensor& R,
                              const torch::Tensor& T) {
  check_points(points, 3, "points");
  return torch::matmul(f64(points), f64(R).transpose(0, 1)) + f64(T).reshape({1, 3});
}

torch::Tensor camera_center(const torch::Tensor& R, const torch::Tensor& T) {
  return -torch::matmul(f64(R).transpose(0, 1), f64(T).reshape({3}));
}

torch::Tensor project(const torch::Tensor& points_cam, const torch::Tensor& K) {
  check_points(points_cam, 3, "points_cam");
  auto p = torch::matmul(f64(points_cam), f64(K).transpose(0, 1));
  return p.slice(1, 0, 2) / p.slice(1, 2, 3);
}

torch::Tensor project_views(const torch::Tensor& points, const torch::Tensor& K,
                            const torch::Tensor& R, const torch::Tensor& T) {
  TORCH_CHECK(points.dim() == 2 && points.size(1) == 3, "points must be (N, 3), got ",
              points.sizes());
  TORCH_CHECK(K.dim() == 3 && R.sizes() == K.sizes() && T.numel() == 3 * K.size(0),
              "project_views: K, R must be (V, 3, 3) and T (V, 3, 1), got ", K.sizes(), ", ",
              R.sizes(), ", ", T.sizes());
  const auto cam = torch::matmul(points.unsqueeze(0), R.transpose(1, 2)) + T.reshape({-1, 1, 3});
  const auto img = torch::matmul(cam, K.transpose(1, 2));
  return img.narrow(2, 0, 2) / img.narrow(2, 2, 1);
}

torch::Tensor project_points(const torch::Tensor& points, const torch::Tensor& K,
                             const torch::Tensor& R, const torch::Tensor& T) {
  check_points(points, 3, "points");
  return project_views(f64(points), f64(K).reshape({1, 3, 3}), f64(R).reshape({1, 3, 3}),
                       f64(T).reshape({1, 3, 1}))
      .squeeze(0);
}

std::pair<torch::Tensor, torch::Tensor> look_at(const torch::Tensor& eye,
                                                const torch::Tensor& target,
                                                const torch::Tensor& up) {
  auto e = f64(eye).reshape({3}), t = f64(target).reshape({3}), u = f64(up).reshape({3});
  auto z = t - e;
  z = z / z.norm();
  // Image y points down, so the camera's x axis is z x up (right-handed, x to the right).
  auto x = torch::cross(z, u, 0);
  TORCH_CHECK(x.norm().item<double>() > 1e-9, "look_at: up is parallel to the view direction");
  x = x / x.norm();
  auto y = torch::cross(z, x, 0);
  auto R = torch::stack({x, y, z}, 0);
  auto T = -torch::matmul(R, e).reshape({3, 1});
  return {R, T};
}

torch::Tensor distort_normalized(const torch::Tensor& xy, const torch::Tensor& D) {
  check_points(xy, 2, "xy");
  const Coeffs c = coeffs(D);
  auto p = f64(xy);
  auto x = p.select(1, 0), y = p.select(1, 1);
  auto r2 = x * x + y * y;
  auto radial = 1.0 + r2 * (c.k1 + r2 * (c.k2 + r2 * c.k3));
  auto xd = x * radial + 2.0 * c.p1 * x * y + c.p2 * (r2 + 2.0 * x * x);
  auto yd = y * radial + c.p1 * (r2 + 2.0 * y * y) + 2.0 * c.p2 * x * y;
  return torch::stack({xd, yd}, 1);
}

torch::Tensor undistort_normalized(const torch::Tensor& xy, const torch::Tensor& D,
                                   int iterations) {
  check_points(xy, 2, "xy");
  const Coeffs c = coeffs(D);
  auto p = f64(xy);
  auto x0 = p.select(1, 0), y0 = p.select(1, 1);
  auto x = x0.clone(), y = y0.clone();
  for (int it = 0; it < iterations; ++it) {
    auto r2 = x * x + y * y;
    auto icdist = 1.0 / (1.0 + r2 * (c.k1 + r2 * (c.k2 + r2 * c.k3)));
    auto dx = 2.0 * c.p1 * x * y + c.p2 * (r2 + 2.0 * x * x);
    auto dy = c.p1 * (r2 + 2.0 * y * y) + 2.0 * c.p2 * x * y;
    x = (x0 - dx) * icdist;
    y = (y0 - dy) * icdist;
  }
  return torch::stack({x, y}, 1);
}

torch::Tensor distort_pixels(const torch::Tensor& uv, const torch::Tensor& K,
                             const torch::Tensor& D) {
  check_points(uv, 2, "uv");
  return normalized_to_pixels(distort_normalized(pixels_to_normalized(f64(uv), K), D), K);
}

torch::Tensor undistort_pixels(const torch::Tensor& uv, const torch::Tensor& K,
                               const torch::Tensor& D) {
  check_points(uv, 2, "uv");
  return normalized_to_pixels(undistort_normalized(pixels_to_normalized(f64(uv), K), D), K);
}

cv::Mat to_cv(const torch::Tensor& t) {
  auto c = f64(t).cpu().contiguous();
  const int rows = c.dim() >= 1 ? static_cast<int>(c.size(0)) : 1;
  const int cols = c.dim() >= 2 ? static_cast<int>(c.numel() / std::max<int64_t>(rows, 1)) : 1;
  return cv::Mat(rows, cols, CV_64F, c.data_ptr<double>()).clone();
}

std::pair<cv::Mat, cv::Mat> distortion_maps(const torch::Tensor& K, const torch::Tensor& D,
                                            int width, int height) {
  cv::Mat grid(1, width * height, CV_64FC2);
  auto* g = grid.ptr<cv::Vec2d>();
  for (int v = 0; v < height; ++v)
    for (int u = 0; u < width; ++u) g[v * width + u] = cv::Vec2d(u, v);
  const cv::Mat k = to_cv(K), d = to_cv(D).reshape(1, 1);
  cv::Mat pinhole;
  // More iterations than the default five, which leave ~0.01 px errors in the corners and
  // would make cv::undistort's round trip visibly inexact (each iteration shrinks the error by
  // about the size of the distortion term, a few percent).
  cv::undistortPoints(grid, pinhole, k, d, cv::noArray(), k,
                      cv::TermCriteria(cv::TermCriteria::COUNT, 12, 0.0));
  cv::Mat map_x(height, width, CV_32F), map_y(height, width, CV_32F);
  const auto* p = pinhole.ptr<cv::Vec2d>();
  for (int v = 0; v < height; ++v)
    for (int u = 0; u < width; ++u) {
      map_x.at<float>(v, u) = static_cast<float>(p[v * width + u][0]);
      map_y.at<float>(v, u) = static_cast<float>(p[v * width + u][1]);
    }
  return {map_x, map_y};
}

cv::Mat distort_image(const cv::Mat& pinhole, const std::pair<cv::Mat, cv::Mat>& maps,
                      int interpolation) {
  cv::Mat out;
  cv::remap(pinhole, out, maps.first, maps.second, interpolation, cv::BORDER_CONSTANT,
            cv::Scalar::all(0));
  return out;
}

}  // namespace th::geometry
