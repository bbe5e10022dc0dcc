#include "render/body_distance.hpp"

#include <ATen/Parallel.h>
#include <torch/torch.h>

#include <algorithm>
#include <cmath>

namespace th::render {

BodyDistance::BodyDistance(const torch::Tensor& vertices, double radius) : radius_(radius) {
  TORCH_CHECK(vertices.dim() == 2 && vertices.size(1) == 3, "body vertices must be (Nv, 3), got ",
              vertices.sizes());
  TORCH_CHECK(radius > 0, "culling radius must be positive, got ", radius);
  const auto v = vertices.detach().to(torch::kCPU, torch::kDouble).contiguous();
  const int64_t nv = v.size(0);
  const double* p = v.data_ptr<double>();
  double lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
  for (int64_t i = 0; i < nv; ++i)
    for (int d = 0; d < 3; ++d) {
      lo[d] = std::min(lo[d], p[3 * i + d]);
      hi[d] = std::max(hi[d], p[3 * i + d]);
    }
  if (nv == 0) lo[0] = lo[1] = lo[2] = hi[0] = hi[1] = hi[2] = 0;
  for (int d = 0; d < 3; ++d) {
    origin_[d] = lo[d];
    dims_[d] = static_cast<int64_t>(std::floor((hi[d] - lo[d]) / radius)) + 1;
  }
  const int64_t cells = dims_[0] * dims_[1] * dims_[2];
  std::vector<int64_t> cell_of(nv);
  cell_start_.assign(cells + 1, 0);
  for (int64_t i = 0; i < nv; ++i) {
    int64_t c[3];
    for (int d = 0; d < 3; ++d)
      c[d] = std::clamp<int64_t>(
          static_cast<int64_t>(std::floor((p[3 * i + d] - origin_[d]) / radius)), 0, dims_[d] - 1);
    cell_of[i] = (c[2] * dims_[1] + c[1]) * dims_[0] + c[0];
    ++cell_start_[cell_of[i] + 1];
  }
  for (int64_t c = 0; c < cells; ++c) cell_start_[c + 1] += cell_start_[c];
  std::vector<int64_t> fill(cell_start_.begin(), cell_start_.end() - 1);
  vertices_.resize(3 * nv);
  for (int64_t i = 0; i < nv; ++i) {
    const int64_t slot = fill[cell_of[i]]++;
    for (int d = 0; d < 3; ++d) vertices_[3 * slot + d] = p[3 * i + d];
  }
}

torch::Tensor BodyDistance::near(const torch::Tensor& pts) const {
  TORCH_CHECK(pts.dim() == 2 && pts.size(1) == 3, "culling points must be (N, 3), got ",
              pts.sizes());
  const auto q = pts.detach().to(torch::kCPU, torch::kDouble).contiguous();
  const int64_t n = q.size(0);
  auto out = torch::zeros({n}, torch::kBool);
  const double* qp = q.data_ptr<double>();
  bool* o = out.data_ptr<bool>();
  const double r2 = radius_ * radius_;
  at::parallel_for(0, n, 4096, [&](int64_t begin, int64_t end) {
    for (int64_t i = begin; i < end; ++i) {
      const double x[3] = {qp[3 * i], qp[3 * i + 1], qp[3 * i + 2]};
      int64_t c[3];
      bool outside = false;
      for (int d = 0; d < 3; ++d) {
        const double f = std::floor((x[d] - origin_[d]) / radius_);
        if (!(f >= -1.0 && f <= static_cast<double>(dims_[d]))) outside = true;  // also NaN
        c[d] = static_cast<int64_t>(f);
      }
      if (outside) continue;
      bool hit = false;
      for (int64_t z = std::max<int64_t>(c[2] - 1, 0);
           z <= std::min(c[2] + 1, dims_[2] - 1) && !hit; ++z)
        for (int64_t y = std::max<int64_t>(c[1] - 1, 0);
             y <= std::min(c[1] + 1, dims_[1] - 1) && !hit; ++y)
          for (int64_t xx = std::max<int64_t>(c[0] - 1, 0);
               xx <= std::min(c[0] + 1, dims_[0] - 1) && !hit; ++xx) {
            const int64_t cell = (z * dims_[1] + y) * dims_[0] + xx;
            for (int64_t k = cell_start_[cell]; k < cell_start_[cell + 1]; ++k) {
              const double dx = vertices_[3 * k] - x[0], dy = vertices_[3 * k + 1] - x[1],
                           dz = vertices_[3 * k + 2] - x[2];
              if (dx * dx + dy * dy + dz * dz < r2) {
                hit = true;
                break;
              }
            }
          }
      o[i] = hit;
    }
  });
  return out.to(pts.device());
}

torch::Tensor BodyDistance::near_brute_force(const torch::Tensor& pts,
                                             const torch::Tensor& vertices, double radius) {
  const auto p = pts.to(torch::kDouble), v = vertices.to(torch::kDouble);
  const auto d2 = (p.unsqueeze(1) - v.unsqueeze(0)).pow(2).sum(-1);
  return std::get<0>(d2.min(1)) < radius * radius;
}

}  // namespace th::render
