#pragma once
// Baking a prepared frame (METHOD 7.1): the network's density on a lattice near the body, coarse
// to fine, and its colour where a ray can see it (along six directions, or from given cameras).
//   1. Density on the coarse lattice (spacing voxel x coarse) over the frame's box; points
//      farther than render.cull_distance from the body are 0, as the exact renderer culls them.
//   2. Coarse cells whose corners are not all of one sign (the surface passes through them),
//      and their neighbours, get the density on the fine lattice (spacing voxel); elsewhere the
//      fine values are the coarse ones, interpolated.
//   3. Colour on the fine points with positive density or next to it (the inside of the body
//      included: with few samples per ray, a ray's first sample with density can lie deep
//      inside): the mean of the network's colours along the six axis directions, or, given the
//      cameras that will look (BakeOptions::eyes), the colour along the direction from each
//      camera's centre; the trunk and the colour head's part before the direction are shared by
//      the directions (model::TransHumanImpl::forward_directions).
//   4. The bricks holding positive density are stored.

#include <functional>
#include <map>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "bake/baked_frame.hpp"
#include "bake/march.hpp"
#include "core/resources.hpp"
#include "inference/session.hpp"
#include "video/camera_path.hpp"

namespace th::bake {

struct BakeOptions {
  double voxel = 0.02;  // fine lattice spacing, metres (the accuracy per spacing: METHOD 7.1)
  int coarse = 2;       // coarse spacing in fine voxels
  int brick = 8;        // cells per brick side
  // Centres (world, metres) of the cameras the bake is for: one colour set each, seen from it.
  // Empty: one colour set, the mean over the six axis directions (any camera).
  std::vector<std::array<double, 3>> eyes;
};

struct BakeReport {
  std::map<std::string, double> seconds;  // per stage: coarse, fine, colour, pack
  int64_t coarse_points = 0;              // lattice points asked of the network, per stage
  int64_t fine_points = 0;
  int64_t color_points = 0;  // points whose colour was asked (six directions or the eyes each)
  double total_seconds() const;
};

// Progress in [0, 1], called between chunks of network work.
using BakeProgress = std::function<void(double)>;

// Bakes `frame` of `session` (the session's device and precision). Throws th::Error for options
// out of range (naming the option), or when its estimated peak memory (bake_estimate) is above
// max_memory_gb, before anything is allocated.
BakedFrame bake_frame(const inference::Session& session, const inference::PreparedFrame& frame,
                      const BakeOptions& options, BakeReport* report = nullptr,
                      const BakeProgress& progress = {});

// Checks options (th::Error naming the one out of range).
void check_options(const BakeOptions& options);

// A frame's box (2, 3) (min; max corner, world) as bake_frame stores it: min x, y, z, max x, y, z.
std::array<double, 6> bake_box(const torch::Tensor& bounds);

// Peak memory of baking a frame whose box is `box` at `options` (METHOD 7.1's stages keep dense
// grids over the whole lattice, and lists of the points near the body), and the network samples
// it asks for; `what` names the frame. Its text names --bake-voxel. Throws th::Error naming
// --bake-voxel when the lattice needs more than 4096 cells along an axis.
resources::Estimate bake_estimate(const std::array<double, 6>& box, const BakeOptions& options,
                                  const inference::Session& session, const std::string& what);
// bake_estimate checked against the session's max_memory_gb: th::Error naming --bake-voxel and
// max_memory_gb when it is above.
void check_bake_memory(const std::array<double, 6>& box, const BakeOptions& options,
                       const inference::Session& session, const std::string& what);

// Views of a session's prepared frames rendered from their bakes: a frame is baked when first
// asked for (the last one is kept), or taken from a file given with use().
class BakedViews {
 public:
  // The march takes the session's render.samples and render.termination_transmittance.
  BakedViews(const inference::Session& session, const BakeOptions& options);

  // `baked` (a file read with read_baked) serves as the bake of `frame`: th::Error naming its
  // file when it was made of another person, frame or reference views, by another checkpoint or
  // with another culling distance.
  void use(BakedFrame baked, const inference::PreparedFrame& frame);
  // The bake of `frame`, made now unless kept.
  const BakedFrame& bake(const inference::PreparedFrame& frame);
  // (H, W, 3) float32 RGB in [0, 1], as Session::render.
  torch::Tensor render(const inference::PreparedFrame& frame, const video::PathCamera& camera,
                       int width, int height);
  // What a video made with it records as its renderer ("baked"), and what it renders from, key by
  // key: the bake's voxel and brick and where it came from (bake.source: "this run" with its
  // coarse factor, or the file given to use() with its size and digest). request.yaml holds both,
  // so frames of one bake are never resumed under another.
  std::string id() const;
  std::vector<std::pair<std::string, std::string>> request_keys() const;
  const BakeReport& last_report() const { return report_; }
  const MarchOptions& march() const { return march_; }

 private:
  const inference::Session& session_;
  BakeOptions options_;
  MarchOptions march_;
  bool kept_ = false;
  bool from_file_ = false;  // baked_ came from use()
  BakedFrame baked_;
  BakeReport report_;
};

// The centre (world, metres) of the camera X_c = R X + T: -R^T T.
std::array<double, 3> camera_centre(const torch::Tensor& R, const torch::Tensor& T);

// The renderer of scored views as every output names it: "exact", or "baked 2 cm" (the bake's
// voxel in centimetres).
std::string renderer_label(ViewRenderer renderer, double voxel);

// Dataset views of loaded samples (evaluation, validation while training) rendered from bakes
// of their frames: one bake per (person, frame, reference views), made when a sample of another
// frame comes and dropped then, so one bake is held at a time (a setting's views come frame by
// frame). The bake's colours are seen from the target cameras the caller names for the frame
// (each view's own direction, no axis mean). The views are marched with the session's
// render.samples and render.termination_transmittance, at the sample's own camera and size.
class SampleBakes {
 public:
  SampleBakes(const inference::Session& session, const BakeOptions& options);

  struct View {
    torch::Tensor ray_rgb, ray_acc;  // (R, 3), (R) at the sample's valid rays (sample.ray_pixel)
    double bake_seconds = 0;         // the frame's bake, when made for this view; else 0
    double march_seconds = 0;
    MarchStats stats;
  };
  // `frame_eyes`: the centres of the target cameras of this sample's frame that will be rendered
  // from its bake (camera_centre); the sample's own is added when missing, and a bake that lacks
  // it is made again.
  View render(const data::Sample& sample,
              const std::vector<std::array<double, 3>>& frame_eyes = {});

  int64_t bakes() const { return bakes_; }  // frames baked so far
  int64_t views() const { return views_; }
  const BakeOptions& options() const { return options_; }

 private:
  const inference::Session& session_;
  BakeOptions options_;
  MarchOptions march_;
  std::optional<BakedFrame> baked_;
  int64_t bakes_ = 0, views_ = 0;
};

}  // namespace th::bake
