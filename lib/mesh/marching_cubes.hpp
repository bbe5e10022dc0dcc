#pragma once
// Marching cubes on a dense scalar grid (METHOD 7: raw density at threshold 20, grid padded by 10
// zero cells, vertices in world coordinates), fed slab by slab so that memory stays bounded
// for any grid: the density is evaluated by the network a z-slab at a time and only the last
// z-slice and one layer of edge-vertex indices are kept here.
//
// Grid layout: a (D, H, W) tensor indexed [k][j][i] = [z][y][x]; sample [k][j][i] lies at
// world  origin + (i * voxel.x, j * voxel.y, k * voxel.z).
//
// Conventions (documented because the mesh's consumers rely on them):
// * Inside is value > threshold (density fields: the body is where sigma is high). Samples
//   equal to the threshold are outside.
// * Faces are wound counter-clockwise seen from outside, so right-hand face normals point
//   outwards, towards lower values (lower density).
// * Vertices are welded: one vertex per grid edge that the surface crosses, shared by every
//   face that uses it (no duplicates), placed by linear interpolation along that edge.
// * Watertight: each cube's polygons are built from per-face segments, and a face's segments
//   depend only on that face's four samples (ambiguous faces, where the two inside corners sit
//   on a diagonal, are resolved by the asymptotic decider on the face's bilinear interpolant;
//   both cubes sharing the face make the same decision). So the two cubes on either side of a
//   face always agree and every mesh edge is shared by exactly two faces, traversed once in
//   each direction, as long as the surface does not reach the grid's outer boundary. Padding
//   (options.pad cells of options.pad_value, below the threshold) guarantees that.
// * The mesh is a 2-manifold combinatorially; triangles can be degenerate (zero area) where
//   the surface passes exactly through a sample, never missing. Polygons are fanned from a
//   vertex chosen so that no fan diagonal can coincide with a neighbouring cube's edge; in the
//   rare cube where none exists, around an extra vertex at the polygon's centroid.

#include <torch/types.h>

#include <array>
#include <cstdint>
#include <vector>

#include "mesh/tri_mesh.hpp"

namespace th::mesh {

// Where the samples lie in the world (see the layout above).
struct GridSpec {
  std::array<double, 3> origin{0, 0, 0};  // world (x, y, z) of sample [0][0][0]
  std::array<double, 3> voxel{1, 1, 1};   // spacing along x, y, z (metres; METHOD 7: 0.005)
};

// A grid with its size: what the density is sampled on (METHOD 7: 5 mm over the frame's bounds).
struct DenseGrid {
  GridSpec spec;
  int64_t depth = 0, height = 0, width = 0;  // D (z), H (y), W (x) samples
};

// The grid over a world box: bounds (2, 3) = [min; max] (x, y, z); samples start at min, step
// `voxel`, and reach max: per axis the samples of numpy's arange(min, max + voxel, voxel), as
// the reference implementation builds them (n = ceil((max + voxel - min) / voxel) in float64).
DenseGrid grid_over_bounds(const torch::Tensor& bounds, double voxel);

// World points of z-slices [z0, z0 + d) of the grid: (d * H * W, 3) float32 (x, y, z) in
// [k][j][i] order, so the network's (d * H * W) densities .reshape({d, H, W}) form the slab
// that MarchingCubes::push takes.
torch::Tensor slab_points(const DenseGrid& grid, int64_t z0, int64_t d);

struct MarchingCubesOptions {
  double threshold = 0.0;  // METHOD 7: 20 on raw sigma
  int pad = 0;             // cells of pad_value added on all six sides (METHOD 7: 10)
  float pad_value = 0.f;   // must be <= threshold for the padding to close the surface
};

// Consumes consecutive z-slices and builds the mesh incrementally.
//
//   MarchingCubes mc(H, W, grid, options);
//   for (each z-slab) mc.push(slab);   // slab: (d, H, W), d >= 1, consecutive in z
//   TriMesh mesh = mc.finish();
//
// The mesh is identical (bit for bit, vertex and face order included) however the grid is cut
// into slabs. Memory: O(H * W) besides the mesh itself.
class MarchingCubes {
 public:
  // height, width: H and W of every slab (before padding).
  MarchingCubes(int64_t height, int64_t width, const GridSpec& grid,
                const MarchingCubesOptions& options = {});

  // slab: (d, H, W) or (H, W) (one slice), any floating dtype, CPU or not. Values must be
  // finite (TORCH_CHECK). Slices are consumed in order: slice 0 of the first slab is z = 0.
  void push(const torch::Tensor& slab);

  // Ends the grid (appends the padding slices) and returns the mesh. Call once.
  TriMesh finish();

  int64_t slices_pushed() const { return slices_in_; }
  int64_t num_verts() const { return int64_t(verts_.size() / 3); }
  int64_t num_faces() const { return int64_t(faces_.size() / 3); }

 private:
  void push_slice(const float* values);  // one padded (Hp, Wp) slice
  void march_layer();                    // the cubes between prev_ and cur_
  int64_t edge_vertex(int edge, int64_t j, int64_t i);
  void emit_polygon(const int* loop, const int64_t* ids, int m);  // m >= 3 cube edges

  int64_t h_, w_, hp_, wp_;  // unpadded and padded slice sizes
  GridSpec grid_;
  MarchingCubesOptions options_;
  bool finished_ = false;
  int64_t slices_in_ = 0;  // unpadded slices pushed by the caller
  int64_t layer_z_ = -1;   // padded z index of prev_ (the layer's bottom plane)

  std::vector<float> prev_, cur_, padded_;  // (Hp, Wp) slices
  // Vertex index per crossed grid edge, -1 where none yet: x-edges (Hp, Wp - 1) and y-edges
  // (Hp - 1, Wp) on the layer's bottom and top planes, z-edges (Hp, Wp) between them. The top
  // plane's maps become the next layer's bottom ones: that is what welds across layers.
  std::vector<int32_t> x_bottom_, x_top_, y_bottom_, y_top_, z_mid_;

  std::vector<float> verts_;    // V * 3
  std::vector<int64_t> faces_;  // F * 3
};

// The whole grid at once: grid (D, H, W) -> mesh (same as pushing it as one slab).
TriMesh marching_cubes(const torch::Tensor& grid, const GridSpec& spec,
                       const MarchingCubesOptions& options = {});

}  // namespace th::mesh
