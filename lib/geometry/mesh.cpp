#include "geometry/mesh.hpp"

#include <torch/torch.h>

namespace th::geometry {

torch::Tensor vertex_normals(const torch::Tensor& verts, const torch::Tensor& faces) {
  TORCH_CHECK(verts.dim() == 2 && verts.size(1) == 3, "vertex_normals: verts must be (V, 3), got ",
              verts.sizes());
  TORCH_CHECK(faces.dim() == 2 && faces.size(1) == 3, "vertex_normals: faces must be (F, 3), got ",
              faces.sizes());
  auto f = faces.to(torch::kInt64);
  auto a = verts.index_select(0, f.select(1, 0));
  auto b = verts.index_select(0, f.select(1, 1));
  auto c = verts.index_select(0, f.select(1, 2));
  auto n = torch::cross(b - a, c - a, 1);  // |n| = 2 x area: area weighting for free
  auto acc = torch::zeros_like(verts);
  for (int k = 0; k < 3; ++k) acc.index_add_(0, f.select(1, k), n);
  return acc / acc.norm(2, 1, true).clamp_min(1e-20);
}

double signed_volume(const torch::Tensor& verts, const torch::Tensor& faces) {
  auto v = verts.to(torch::kFloat64);
  auto f = faces.to(torch::kInt64);
  auto a = v.index_select(0, f.select(1, 0));
  auto b = v.index_select(0, f.select(1, 1));
  auto c = v.index_select(0, f.select(1, 2));
  return (a * torch::cross(b, c, 1)).sum().item<double>() / 6.0;
}

}  // namespace th::geometry
