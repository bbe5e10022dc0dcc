#pragma once
// The triangle mesh that marching cubes produces and the PLY writer, the preview renderer and
// the mesh app consume (METHOD 7).

#include <torch/types.h>

namespace th::mesh {

// Faces are wound counter-clockwise seen from outside (right-hand normal points outwards), the
// convention of geometry::vertex_normals and geometry::signed_volume.
struct TriMesh {
  torch::Tensor verts;   // (V, 3) float32 world coordinates (metres)
  torch::Tensor faces;   // (F, 3) int64 vertex indices
  torch::Tensor colors;  // (V, 3) uint8 RGB per vertex, or undefined (no colours)

  int64_t num_verts() const { return verts.defined() ? verts.size(0) : 0; }
  int64_t num_faces() const { return faces.defined() ? faces.size(0) : 0; }
};

// Checks the shapes and dtypes above and that every face index is in range (TORCH_CHECK: a
// malformed mesh is a bug, not a user error). `what` names the mesh in the message.
void check_mesh(const TriMesh& mesh, const char* what);

// Total triangle area (in the units of verts squared).
double surface_area(const TriMesh& mesh);

}  // namespace th::mesh
