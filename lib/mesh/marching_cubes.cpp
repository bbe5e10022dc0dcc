#include "mesh/marching_cubes.hpp"

#include <torch/torch.h>

#include <algorithm>
#include <cmath>
#include <limits>

namespace th::mesh {
namespace {

// Cube numbering. Corner c = dx + 2 dy + 4 dz. Edges: 0..3 along x (index dy + 2 dz), 4..7
// along y (dx + 2 dz), 8..11 along z (dx + 2 dy). Each face lists its corners counter-clockwise
// seen from outside the cube and edge q joins face corners q and q + 1.
struct CubeTables {
  int edge_corners[12][2];  // lower corner first (the same order for every cube on that edge)
  int edge_axis[12];
  int face_corners[6][4];
  int face_edges[6][4];
  int edge_faces[12] = {0};  // bit f set: the edge lies on face f

  static int edge_between(int c1, int c2) {
    const int diff = c1 ^ c2;
    const int lo = std::min(c1, c2);
    if (diff == 1) return ((lo >> 1) & 1) + 2 * ((lo >> 2) & 1);
    if (diff == 2) return 4 + (lo & 1) + 2 * ((lo >> 2) & 1);
    return 8 + (lo & 1) + 2 * ((lo >> 1) & 1);
  }

  CubeTables() {
    for (int c1 = 0; c1 < 8; ++c1)
      for (int axis = 0; axis < 3; ++axis) {
        if ((c1 >> axis) & 1) continue;
        const int c2 = c1 | (1 << axis);
        const int e = edge_between(c1, c2);
        edge_corners[e][0] = c1;
        edge_corners[e][1] = c2;
        edge_axis[e] = axis;
      }
    // Face normal +a: (u, v, n) right-handed means u = a + 1, v = a + 2 (cyclic); for -a swap.
    const int uv[4][2] = {{0, 0}, {1, 0}, {1, 1}, {0, 1}};  // counter-clockwise in (u, v)
    for (int axis = 0; axis < 3; ++axis)
      for (int side = 0; side < 2; ++side) {
        const int f = 2 * axis + side;
        const int a1 = (axis + 1) % 3, a2 = (axis + 2) % 3;
        const int u = side ? a1 : a2, v = side ? a2 : a1;
        for (int q = 0; q < 4; ++q)
          face_corners[f][q] = (side << axis) | (uv[q][0] << u) | (uv[q][1] << v);
        for (int q = 0; q < 4; ++q) {
          face_edges[f][q] = edge_between(face_corners[f][q], face_corners[f][(q + 1) % 4]);
          edge_faces[face_edges[f][q]] |= 1 << f;
        }
      }
  }
};

const CubeTables& tables() {
  static const CubeTables t;
  return t;
}

}  // namespace

MarchingCubes::MarchingCubes(int64_t height, int64_t width, const GridSpec& grid,
                             const MarchingCubesOptions& options)
    : h_(height), w_(width), grid_(grid), options_(options) {
  TORCH_CHECK(height >= 1 && width >= 1, "MarchingCubes: empty slice ", height, "x", width);
  TORCH_CHECK(options.pad >= 0, "MarchingCubes: pad must be >= 0, got ", options.pad);
  for (int a = 0; a < 3; ++a)
    TORCH_CHECK(grid.voxel[a] > 0, "MarchingCubes: voxel sizes must be > 0");
  hp_ = h_ + 2 * options.pad;
  wp_ = w_ + 2 * options.pad;
  const auto plane = static_cast<size_t>(hp_ * wp_);
  padded_.assign(plane, options.pad_value);
  x_bottom_.assign(static_cast<size_t>(hp_ * (wp_ - 1)), -1);
  x_top_ = x_bottom_;
  y_bottom_.assign(static_cast<size_t>((hp_ - 1) * wp_), -1);
  y_top_ = y_bottom_;
  z_mid_.assign(plane, -1);
  // Leading padding slices (z < 0 in grid coordinates).
  const std::vector<float> pad_slice(plane, options.pad_value);
  for (int p = 0; p < options.pad; ++p) push_slice(pad_slice.data());
}

void MarchingCubes::push(const torch::Tensor& slab) {
  TORCH_CHECK(!finished_, "MarchingCubes: push after finish");
  TORCH_CHECK(slab.is_floating_point(), "MarchingCubes: slab must be floating point, got ",
              slab.scalar_type());
  auto s = slab.detach().to(torch::kCPU, torch::kFloat32).contiguous();
  if (s.dim() == 2) s = s.unsqueeze(0);
  TORCH_CHECK(s.dim() == 3 && s.size(1) == h_ && s.size(2) == w_,
              "MarchingCubes: slab must be (d, ", h_, ", ", w_, "), got ", slab.sizes());
  TORCH_CHECK(torch::isfinite(s).all().item<bool>(),
              "MarchingCubes: slab starting at z = ", slices_in_, " holds non-finite values");
  const int pad = options_.pad;
  const float* src = s.data_ptr<float>();
  for (int64_t k = 0; k < s.size(0); ++k) {
    const float* slice = src + k * h_ * w_;
    if (pad == 0) {
      push_slice(slice);
    } else {
      // The border of padded_ keeps pad_value; only the interior is overwritten.
      for (int64_t j = 0; j < h_; ++j)
        std::copy(slice + j * w_, slice + (j + 1) * w_, &padded_[(j + pad) * wp_ + pad]);
      push_slice(padded_.data());
    }
    ++slices_in_;
  }
}

TriMesh MarchingCubes::finish() {
  TORCH_CHECK(!finished_, "MarchingCubes: finish called twice");
  const std::vector<float> pad_slice(static_cast<size_t>(hp_ * wp_), options_.pad_value);
  for (int p = 0; p < options_.pad; ++p) push_slice(pad_slice.data());
  finished_ = true;

  TriMesh mesh;
  const auto nv = static_cast<int64_t>(verts_.size() / 3);
  const auto nf = static_cast<int64_t>(faces_.size() / 3);
  mesh.verts = torch::from_blob(verts_.data(), {nv, 3}, torch::kFloat32).clone();
  mesh.faces = torch::from_blob(faces_.data(), {nf, 3}, torch::kInt64).clone();
  std::vector<float>().swap(verts_);
  std::vector<int64_t>().swap(faces_);
  return mesh;
}

void MarchingCubes::push_slice(const float* values) {
  const auto plane = static_cast<size_t>(hp_ * wp_);
  if (layer_z_ < 0) {
    prev_.assign(values, values + plane);
    cur_.resize(plane);
    layer_z_ = 0;
    return;
  }
  std::copy(values, values + plane, cur_.begin());
  march_layer();
  std::swap(prev_, cur_);
  ++layer_z_;
  // The top plane's edges are the next layer's bottom plane's.
  std::swap(x_bottom_, x_top_);
  std::swap(y_bottom_, y_top_);
  std::fill(x_top_.begin(), x_top_.end(), -1);
  std::fill(y_top_.begin(), y_top_.end(), -1);
  std::fill(z_mid_.begin(), z_mid_.end(), -1);
}

void MarchingCubes::march_layer() {
  const CubeTables& t = tables();
  const double threshold = options_.threshold;
  double d[8];   // corner value - threshold
  int next[12];  // segment graph: cube edge -> following cube edge
  int loop[12];
  int64_t ids[12];

  for (int64_t j = 0; j + 1 < hp_; ++j) {
    const float* a0 = &prev_[j * wp_];
    const float* a1 = a0 + wp_;
    const float* b0 = &cur_[j * wp_];
    const float* b1 = b0 + wp_;
    for (int64_t i = 0; i + 1 < wp_; ++i) {
      const float v[8] = {a0[i], a0[i + 1], a1[i], a1[i + 1], b0[i], b0[i + 1], b1[i], b1[i + 1]};
      int config = 0;
      for (int c = 0; c < 8; ++c)
        if (v[c] > threshold) config |= 1 << c;
      if (config == 0 || config == 255) continue;
      for (int c = 0; c < 8; ++c) d[c] = double(v[c]) - threshold;
      auto in = [config](int c) { return (config >> c) & 1; };

      // Per-face segments, oriented with the inside on their left seen from outside the cube:
      // from the edge where the counter-clockwise walk leaves the inside to the edge where it
      // re-enters. They chain into closed loops around the cube.
      std::fill(next, next + 12, -1);
      for (int f = 0; f < 6; ++f) {
        const int* p = t.face_corners[f];
        const int* e = t.face_edges[f];
        const int n_in = in(p[0]) + in(p[1]) + in(p[2]) + in(p[3]);
        if (n_in == 0 || n_in == 4) continue;
        const bool ambiguous = n_in == 2 && in(p[0]) == in(p[2]);
        if (ambiguous) {
          // Asymptotic decider: the bilinear interpolant's saddle is inside iff the product of
          // the inside diagonal exceeds the outside one; then the inside corners are joined.
          // Symmetric in the face's corners, so the neighbouring cube decides the same.
          const int q0 = in(p[0]) ? 0 : 1;  // the inside corners are q0 and q0 + 2
          const bool join = d[p[q0]] * d[p[q0 + 2]] > d[p[q0 + 1]] * d[p[(q0 + 3) % 4]];
          for (int q = q0; q < 4; q += 2) next[e[q]] = join ? e[(q + 1) % 4] : e[(q + 3) % 4];
        } else {
          int exit = -1, entry = -1;
          for (int q = 0; q < 4; ++q) {
            const int here = in(p[q]), there = in(p[(q + 1) % 4]);
            if (here && !there) exit = e[q];
            if (!here && there) entry = e[q];
          }
          next[exit] = entry;
        }
      }

      // Each loop becomes a polygon, fanned into triangles. The loop runs counter-clockwise
      // around the inside corners seen from outside the cube, so its right-hand normal points
      // towards the inside: triangles are emitted reversed to face outwards.
      bool used[12] = {false};
      for (int start = 0; start < 12; ++start) {
        if (next[start] < 0 || used[start]) continue;
        int m = 0;
        int e = start;
        do {
          TORCH_CHECK(m < 12 && e >= 0, "MarchingCubes: open loop in cube config ", config);
          used[e] = true;
          loop[m++] = e;
          e = next[e];
        } while (e != start);
        for (int q = 0; q < m; ++q) ids[q] = edge_vertex(loop[q], j, i);
        emit_polygon(loop, ids, m);
      }
    }
  }
}

void MarchingCubes::emit_polygon(const int* loop, const int64_t* ids, int m) {
  const CubeTables& t = tables();
  // A fan diagonal between two vertices on the same cube face could also be an edge of the
  // neighbouring cube's polygons (both of an ambiguous face's segments in one loop), making
  // that mesh edge shared by four faces. So fan from a vertex whose diagonals all join
  // vertices on no common face (only cubes sharing a face share two vertices); if there is
  // none, fan around a new vertex at the polygon's centroid, whose edges no other cube has.
  int apex = -1;
  for (int s = 0; s < m && apex < 0; ++s) {
    bool ok = true;
    for (int q = 2; q + 1 < m && ok; ++q)
      ok = (t.edge_faces[loop[s]] & t.edge_faces[loop[(s + q) % m]]) == 0;
    if (ok) apex = s;
  }
  if (apex >= 0) {
    for (int q = 1; q + 1 < m; ++q) {
      faces_.push_back(ids[apex]);
      faces_.push_back(ids[(apex + q + 1) % m]);
      faces_.push_back(ids[(apex + q) % m]);
    }
    return;
  }
  double centroid[3] = {0, 0, 0};
  for (int q = 0; q < m; ++q)
    for (int a = 0; a < 3; ++a) centroid[a] += verts_[3 * ids[q] + a];
  for (int a = 0; a < 3; ++a) verts_.push_back(static_cast<float>(centroid[a] / m));
  const int64_t c = int64_t(verts_.size() / 3) - 1;
  for (int q = 0; q < m; ++q) {
    faces_.push_back(c);
    faces_.push_back(ids[(q + 1) % m]);
    faces_.push_back(ids[q]);
  }
}

int64_t MarchingCubes::edge_vertex(int edge, int64_t j, int64_t i) {
  const CubeTables& t = tables();
  int32_t* slot;
  if (edge < 4) {
    const int dy = edge & 1, dz = edge >> 1;
    slot = &(dz ? x_top_ : x_bottom_)[(j + dy) * (wp_ - 1) + i];
  } else if (edge < 8) {
    const int dx = edge & 1, dz = (edge - 4) >> 1;
    slot = &(dz ? y_top_ : y_bottom_)[j * wp_ + i + dx];
  } else {
    const int dx = edge & 1, dy = (edge - 8) >> 1;
    slot = &z_mid_[(j + dy) * wp_ + i + dx];
  }
  if (*slot >= 0) return *slot;

  // The crossing by linear interpolation from the edge's lower corner; the values come from
  // the planes directly so that every cube sharing the edge would compute the same point.
  const int c1 = t.edge_corners[edge][0], c2 = t.edge_corners[edge][1];
  auto value = [&](int c) {
    const auto& plane = (c >> 2) & 1 ? cur_ : prev_;
    return double(plane[(j + ((c >> 1) & 1)) * wp_ + i + (c & 1)]) - options_.threshold;
  };
  const double d1 = value(c1), d2 = value(c2);
  const double frac = d1 / (d1 - d2);  // d1, d2 on opposite sides of 0: no division by zero
  double idx[3] = {double(i + (c1 & 1)), double(j + ((c1 >> 1) & 1)),
                   double(layer_z_ + ((c1 >> 2) & 1))};
  idx[t.edge_axis[edge]] += frac;
  for (int a = 0; a < 3; ++a)
    verts_.push_back(
        static_cast<float>(grid_.origin[a] + (idx[a] - options_.pad) * grid_.voxel[a]));
  const int64_t id = int64_t(verts_.size() / 3) - 1;
  TORCH_CHECK(id < std::numeric_limits<int32_t>::max(), "MarchingCubes: too many vertices");
  *slot = static_cast<int32_t>(id);
  return id;
}

DenseGrid grid_over_bounds(const torch::Tensor& bounds, double voxel) {
  TORCH_CHECK(bounds.numel() == 6, "grid_over_bounds: bounds must be (2, 3), got ", bounds.sizes());
  TORCH_CHECK(voxel > 0, "grid_over_bounds: voxel must be > 0, got ", voxel);
  auto b = bounds.to(torch::kFloat64).cpu().reshape({2, 3});
  DenseGrid grid;
  int64_t n[3];
  for (int a = 0; a < 3; ++a) {
    const double lo = b[0][a].item<double>(), hi = b[1][a].item<double>();
    TORCH_CHECK(hi >= lo, "grid_over_bounds: max < min on axis ", a);
    grid.spec.origin[a] = lo;
    grid.spec.voxel[a] = voxel;
    // Exactly numpy's arange length, ceil((stop - start) / step), rounding included.
    const double count = std::ceil((hi + voxel - lo) / voxel);
    TORCH_CHECK(count < double(int64_t{1} << 40), "grid_over_bounds: ", count, " points on axis ",
                a, " at voxel ", voxel, " (too fine to count)");
    n[a] = static_cast<int64_t>(count);
  }
  grid.width = n[0];
  grid.height = n[1];
  grid.depth = n[2];
  return grid;
}

torch::Tensor slab_points(const DenseGrid& grid, int64_t z0, int64_t d) {
  TORCH_CHECK(z0 >= 0 && d >= 0 && z0 + d <= grid.depth, "slab_points: slices [", z0, ", ", z0 + d,
              ") outside the grid's ", grid.depth);
  const auto& g = grid.spec;
  auto axis = [](double origin, double step, int64_t first, int64_t n) {
    return origin + step * torch::arange(first, first + n, torch::kFloat64);
  };
  auto zyx = torch::meshgrid(
      {axis(g.origin[2], g.voxel[2], z0, d), axis(g.origin[1], g.voxel[1], 0, grid.height),
       axis(g.origin[0], g.voxel[0], 0, grid.width)},
      "ij");
  return torch::stack({zyx[2], zyx[1], zyx[0]}, -1).reshape({-1, 3}).to(torch::kFloat32);
}

TriMesh marching_cubes(const torch::Tensor& grid, const GridSpec& spec,
                       const MarchingCubesOptions& options) {
  TORCH_CHECK(grid.dim() == 3, "marching_cubes: grid must be (D, H, W), got ", grid.sizes());
  MarchingCubes mc(grid.size(1), grid.size(2), spec, options);
  mc.push(grid);
  return mc.finish();
}

}  // namespace th::mesh
