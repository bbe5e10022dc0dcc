#pragma once
// Topology of a triangle mesh computed directly from its faces, independently of the code that
// built it: edge usage, orientation, Euler characteristic and connected components.

#include <torch/torch.h>

#include <cstdint>
#include <numeric>
#include <unordered_map>
#include <vector>

#include "mesh/tri_mesh.hpp"

namespace th::test {

struct Topology {
  int64_t verts = 0;  // vertices used by some face
  int64_t edges = 0;  // undirected
  int64_t faces = 0;
  int64_t boundary_edges = 0;     // used by one face
  int64_t nonmanifold_edges = 0;  // used by three or more faces
  int64_t misoriented_edges = 0;  // used twice but in the same direction
  int64_t components = 0;         // face-connected through shared vertices
  int64_t euler() const { return verts - edges + faces; }
  bool closed() const { return boundary_edges == 0 && nonmanifold_edges == 0; }
  bool oriented() const { return misoriented_edges == 0; }
};

inline Topology topology(const mesh::TriMesh& m) {
  auto f = m.faces.contiguous();
  const int64_t* fp = f.data_ptr<int64_t>();
  const int64_t nf = f.size(0), nv = m.verts.size(0);
  // Directed edge (a, b) -> count; key a * nv + b.
  std::unordered_map<int64_t, int> directed;
  directed.reserve(static_cast<size_t>(3 * nf));
  std::vector<int64_t> parent(nv);
  std::iota(parent.begin(), parent.end(), 0);
  auto find = [&](int64_t x) {
    while (parent[x] != x) x = parent[x] = parent[parent[x]];
    return x;
  };
  std::vector<char> used(nv, 0);
  for (int64_t t = 0; t < nf; ++t)
    for (int k = 0; k < 3; ++k) {
      const int64_t a = fp[3 * t + k], b = fp[3 * t + (k + 1) % 3];
      ++directed[a * nv + b];
      used[a] = 1;
      parent[find(a)] = find(b);
    }
  Topology top;
  top.faces = nf;
  for (int64_t v = 0; v < nv; ++v)
    if (used[v]) {
      ++top.verts;
      if (find(v) == v) ++top.components;
    }
  for (const auto& [key, count] : directed) {
    const int64_t a = key / nv, b = key % nv;
    auto it = directed.find(b * nv + a);
    const int back = it == directed.end() ? 0 : it->second;
    if (a < b || back == 0) {  // visit each undirected edge once
      ++top.edges;
      const int uses = count + back;
      if (uses == 1) ++top.boundary_edges;
      if (uses > 2) ++top.nonmanifold_edges;
      if (uses == 2 && (count != 1 || back != 1)) ++top.misoriented_edges;
    }
  }
  return top;
}

// Number of vertices whose position equals another vertex's exactly (welding check).
inline int64_t duplicate_vertices(const mesh::TriMesh& m) {
  auto v = m.verts.to(torch::kFloat64);
  auto unique = std::get<0>(torch::unique_dim(v, 0));
  return v.size(0) - unique.size(0);
}

}  // namespace th::test
