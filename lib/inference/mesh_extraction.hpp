#pragma once
// Mesh extraction (METHOD 7): the network's raw density on a grid over the frame's box (5 mm by
// default), zero farther than the culling distance from the body, marching cubes at a
// threshold (20) with 10 cells of zero padding, vertices in world coordinates, a binary PLY,
// optional vertex colours from the colour branch looking along the vertex normal, and a
// preview PNG rendered with the project's rasteriser. The grid is evaluated a z-slab at a time
// and marching cubes consumes it slab by slab, so memory is bounded for any resolution.

#include <array>
#include <filesystem>
#include <string>

#include "inference/session.hpp"
#include "mesh/tri_mesh.hpp"

namespace th::inference {

struct MeshRequest {
  std::string human;        // empty: the setting's first person
  int frame = -1;           // annots index; -1: the setting's first frame of that person
  double voxel = 0.005;     // metres
  double threshold = 20.0;  // on raw sigma
  bool colors = false;      // vertex colours from the colour branch
  int view = 3;             // the preview looks from this camera's direction (and from the side)
  int64_t slab_points = 1 << 20;  // grid points evaluated per slab (memory bound)
};

struct MeshSummary {
  mesh::TriMesh mesh;
  std::array<int64_t, 3> grid{0, 0, 0};  // samples along x, y, z
  int64_t evaluated_points = 0;          // within the culling distance of the body
  double seconds = 0;
  std::filesystem::path ply, preview;
};

// A request resolved and checked against the data, before any density is evaluated (also what
// `transhuman-mesh --dry-run` checks): voxel, threshold, person, frame, preview camera, and the
// memory the grid needs against max_memory_gb.
struct MeshPlan {
  int human = 0;
  int frame = 0;
  PreparedFrame prepared;
  std::array<int64_t, 3> grid{0, 0, 0};
};
MeshPlan plan_mesh(const Session& session, const MeshRequest& request);

// Writes <out_dir>/<human>_frame<NNNN>.ply and <...>_preview.png. Throws th::Error for a bad
// request; an empty mesh (nothing above the threshold) is an error that names the threshold
// and the largest density found.
MeshSummary extract_mesh(const Session& session, const MeshRequest& request,
                         const std::filesystem::path& out_dir);

}  // namespace th::inference
