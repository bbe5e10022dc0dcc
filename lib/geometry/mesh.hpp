#pragma once
// Triangle-mesh helpers shared by the renderers and the synthetic body.

#include <torch/types.h>

namespace th::geometry {

// Area-weighted unit vertex normals: verts (V, 3), faces (F, 3) integer -> (V, 3) in verts'
// dtype. Faces wound counter-clockwise seen from outside give outward normals. Vertices on
// no face get a zero normal.
torch::Tensor vertex_normals(const torch::Tensor& verts, const torch::Tensor& faces);

// Signed volume enclosed by a closed, consistently wound mesh (positive when outward):
// verts (V, 3), faces (F, 3) -> scalar.
double signed_volume(const torch::Tensor& verts, const torch::Tensor& faces);

}  // namespace th::geometry
