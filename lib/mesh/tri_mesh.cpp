#include "mesh/tri_mesh.hpp"

#include <torch/torch.h>

namespace th::mesh {

void check_mesh(const TriMesh& mesh, const char* what) {
  TORCH_CHECK(mesh.verts.defined() && mesh.verts.dim() == 2 && mesh.verts.size(1) == 3, what,
              ": verts must be (V, 3)");
  TORCH_CHECK(mesh.verts.scalar_type() == torch::kFloat32, what, ": verts must be float32, got ",
              mesh.verts.scalar_type());
  TORCH_CHECK(mesh.faces.defined() && mesh.faces.dim() == 2 && mesh.faces.size(1) == 3, what,
              ": faces must be (F, 3)");
  TORCH_CHECK(mesh.faces.scalar_type() == torch::kInt64, what, ": faces must be int64, got ",
              mesh.faces.scalar_type());
  if (mesh.faces.numel() > 0) {
    TORCH_CHECK(mesh.faces.min().item<int64_t>() >= 0 &&
                    mesh.faces.max().item<int64_t>() < mesh.verts.size(0),
                what, ": face index out of range for ", mesh.verts.size(0), " vertices");
  }
  if (mesh.colors.defined()) {
    TORCH_CHECK(mesh.colors.dim() == 2 && mesh.colors.size(1) == 3 &&
                    mesh.colors.size(0) == mesh.verts.size(0) &&
                    mesh.colors.scalar_type() == torch::kUInt8,
                what, ": colors must be (V, 3) uint8, got ", mesh.colors.sizes(), " ",
                mesh.colors.scalar_type());
  }
}

double surface_area(const TriMesh& mesh) {
  check_mesh(mesh, "surface_area");
  if (mesh.faces.numel() == 0) return 0.0;
  auto v = mesh.verts.to(torch::kFloat64);
  auto a = v.index_select(0, mesh.faces.select(1, 0));
  auto b = v.index_select(0, mesh.faces.select(1, 1));
  auto c = v.index_select(0, mesh.faces.select(1, 2));
  return 0.5 * torch::cross(b - a, c - a, 1).norm(2, 1).sum().item<double>();
}

}  // namespace th::mesh
