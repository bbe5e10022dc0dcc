#pragma once
// "Is any body vertex within r of this point?" for the distance culling of METHOD 4 (progressive
// rendering) and 7 (mesh extraction), answered from a uniform grid of cell size r built once per
// frame: a point only needs the vertices of its own and the 26 neighbouring cells, never an
// N x Nv distance matrix (METHOD 9).

#include <torch/types.h>

#include <cstdint>
#include <vector>

namespace th::render {

class BodyDistance {
 public:
  // vertices: (Nv, 3) world coordinates of the posed body; radius r in metres.
  BodyDistance(const torch::Tensor& vertices, double radius);

  // pts: (N, 3) -> (N) bool on the device of pts: true where some vertex is closer than r
  // (strictly, as the reference's `dist < 0.1`).
  torch::Tensor near(const torch::Tensor& pts) const;

  double radius() const { return radius_; }
  int64_t num_vertices() const { return static_cast<int64_t>(vertices_.size() / 3); }

  // The same answer from all pairwise distances (reference for tests).
  static torch::Tensor near_brute_force(const torch::Tensor& pts, const torch::Tensor& vertices,
                                        double radius);

 private:
  double radius_;
  double origin_[3];
  int64_t dims_[3];
  std::vector<double> vertices_;     // sorted by cell, xyz interleaved
  std::vector<int64_t> cell_start_;  // per cell: first vertex; size cells + 1
};

}  // namespace th::render
