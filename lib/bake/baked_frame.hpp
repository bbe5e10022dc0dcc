#pragma once
// A frame baked to a sparse grid (METHOD 7.1): for one person, one frame and its reference views,
// the network's raw density and its colour on the points of a regular lattice near the body, so
// that any later view of the frame is a ray march through the grid, without the network.
//
// The lattice has spacing `voxel` from `origin` and `cells` cells per axis. It is stored in
// bricks of `brick` cells per side; a brick holds its (brick + 1)^3 lattice points (its faces
// duplicated with its neighbours, so a trilinear lookup never leaves its brick). Only bricks
// where the density is positive somewhere are stored; elsewhere the density is 0, as the exact
// renderer's culled samples.
//
// Colour per lattice point: the mean of the network's colours along the six axis directions.
// The direction is not kept: on the demo checkpoint, degree-1 spherical harmonics fitted to the
// six colours scored no better against the ground truth than their mean (METHOD 7.1). A bake
// for known cameras (an evaluation's target views) holds instead one colour per camera, seen
// from its centre: a colour set per eye.

#include <array>
#include <cstdint>
#include <filesystem>
#include <string>
#include <utility>
#include <vector>

namespace th::bake {

// Floats of colour per lattice point: r, g, b in [0, 1].
constexpr int kColorDims = 3;

struct BakedFrame {
  // What was baked: the person's folder name, the frame (annots index), the checkpoint's
  // identity (Session::checkpoint_id) and the reference cameras.
  std::string human;
  int frame = 0;
  std::string checkpoint;
  std::vector<int> reference_views;

  double voxel = 0;                // lattice spacing, metres
  std::array<double, 3> origin{};  // world position of lattice point (0, 0, 0)
  std::array<int64_t, 3> cells{};  // cells per axis (cells + 1 lattice points)
  int brick = 8;                   // cells per brick side
  std::array<double, 6> box{};     // the frame's box (min x, y, z, max x, y, z): rays' near/far
  double cull_distance = 0;        // the renderer's culling distance when baked (render key)

  // Cameras' centres (world) the colours are seen from, one colour set each; empty: one set, the
  // mean over the six axis directions. Bakes with eyes stay in memory (write_baked refuses them).
  std::vector<std::array<double, 3>> eyes;

  // Per brick of the brick grid (x slowest, z fastest): its slot, or -1 where nothing is stored.
  std::vector<int32_t> slot;
  // Per slot: density (brick + 1)^3 and colour (brick + 1)^3 x color_sets() x kColorDims,
  // lattice points x slowest, z fastest.
  std::vector<float> density;
  std::vector<float> color;

  // Where it was read from (read_baked): the file as named, and its size and content digest
  // ("<n> bytes, FNV-1a 64 <hex>"), which a render's request.yaml records. Empty for a bake
  // made in this process.
  std::string file;
  std::string digest;

  std::array<int64_t, 3> bricks() const;  // bricks per axis: ceil(cells / brick)
  int64_t points_per_brick() const { return int64_t(brick + 1) * (brick + 1) * (brick + 1); }
  int64_t stored_bricks() const;
  int color_sets() const { return eyes.empty() ? 1 : int(eyes.size()); }
  int64_t bytes() const;  // of the grid in memory (what a file holds, header aside)
};

// Writes `frame` to the new file `path` (binary: a versioned header, then the arrays). The file
// appears complete or not at all, and only where nothing was: th::Error naming it when it exists,
// or when another writer made it while this one wrote (of two writers, one wins), or when the
// frame has eyes (its colours serve only its cameras).
void write_baked(const BakedFrame& frame, const std::filesystem::path& path);

// Reads and checks a file written by write_baked: a regular file (a FIFO or a device is refused
// before it is opened), its format and version, the header's length (1 MiB at most) and every
// size against the file's length before the arrays are read, slots in range and unique, finite
// values. With `max_bytes` > 0, arrays of more bytes are refused before they are allocated.
// Throws th::Error naming the file and what is wrong.
BakedFrame read_baked(const std::filesystem::path& path, double max_bytes = 0);

// Checks that `path` can take a new bake file before any work is done: it does not exist, its
// folder does, and it lies in none of `places` (what, path: a run folder, the data root) nor is
// one of them (an input file). Throws th::Error naming `option` ("--bake-out") and the path.
void check_bake_destination(const std::filesystem::path& path, const std::string& option,
                            const std::vector<std::pair<std::string, std::string>>& places);

}  // namespace th::bake
