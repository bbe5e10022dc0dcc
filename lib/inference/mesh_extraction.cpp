#include "inference/mesh_extraction.hpp"

#include <spdlog/spdlog.h>
#include <torch/torch.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <opencv2/core.hpp>

#include "core/error.hpp"
#include "core/progress.hpp"
#include "core/resources.hpp"
#include "geometry/mesh.hpp"
#include "mesh/marching_cubes.hpp"
#include "mesh/ply.hpp"
#include "mesh/preview.hpp"
#include "render/chunks.hpp"
#include "video/frame_writer.hpp"

namespace th::inference {
namespace fs = std::filesystem;

namespace {

constexpr int kPad = 10;  // zero cells around the grid (METHOD 7)

resources::Estimate mesh_estimate(const torch::Tensor& bounds, const MeshRequest& request,
                                  const Session& session, const PreparedFrame& prepared) {
  double n[3], side[3];
  for (int a = 0; a < 3; ++a) {
    side[a] = (bounds[1][a] - bounds[0][a]).item<double>();
    n[a] = std::ceil((side[a] + request.voxel) / request.voxel);
  }
  const double plane = (n[0] + 2 * kPad) * (n[1] + 2 * kPad), points = n[0] * n[1] * n[2];
  const double slab =
      std::max(1.0, std::floor(double(request.slab_points) / (n[0] * n[1]))) * n[0] * n[1];
  // Marching cubes keeps three padded slices and five edge-index maps; a slab of points is
  // evaluated at once (float64 coordinates, density, culling indices); the mesh grows with the
  // surface: about two vertices per voxel of the box's surface area, two faces per vertex.
  const double area = 2 * (side[0] * side[1] + side[1] * side[2] + side[0] * side[2]);
  const double verts = 2 * area / (request.voxel * request.voxel);
  const double cache = prepared.cache.nbytes();
  resources::Estimate e;
  e.what = fmt::format("mesh grid {:.0f} x {:.0f} x {:.0f} at {} mm", n[0], n[1], n[2],
                       request.voxel * 1000);
  e.bytes = plane * 8 * 4 + slab * 48 + verts * (12 + 2 * 24) + cache +
            double(session.config().render.chunk_points) * resources::kBytesPerChunkPoint;
  e.samples = points;
  e.threads = session.device().is_cpu() ? torch::get_num_threads() : 0;
  return e;
}

}  // namespace

MeshPlan plan_mesh(const Session& session, const MeshRequest& request) {
  if (!(request.voxel > 0) || !std::isfinite(request.voxel))
    fail("mesh voxel size must be a positive number, got ", request.voxel);
  if (!(request.threshold >= 0) || !std::isfinite(request.threshold))
    fail("mesh threshold must be a finite number >= 0, got ", request.threshold,
         " (the grid away from the body and its padding hold density 0: a negative level puts all "
         "of it inside)");
  MeshPlan plan;
  plan.human = session.find_human(request.human);
  const auto& human = session.human(plan.human);
  plan.frame = request.frame;
  if (plan.frame < 0) {
    const auto listed = session.setting_frames(plan.human);
    if (listed.empty())
      fail("setting '", session.config().eval.setting, "' lists no frames of ", human.name());
    plan.frame = listed.front();
  }
  if (request.view < 0 || request.view >= human.num_cameras())
    fail(human.name(), ": camera ", request.view, " out of range [0, ", human.num_cameras(), ")");
  plan.prepared = session.prepare(plan.human, plan.frame, request.view);
  // What the grid costs is checked first (a too fine voxel is refused in a second, not after
  // filling memory).
  const auto bounds = plan.prepared.sample.body.bounds.to(torch::kFloat64).reshape({2, 3});
  resources::check(mesh_estimate(bounds, request, session, plan.prepared),
                   session.config().max_memory_gb);
  const auto grid = mesh::grid_over_bounds(bounds, request.voxel);
  plan.grid = {grid.width, grid.height, grid.depth};
  return plan;
}

MeshSummary extract_mesh(const Session& session, const MeshRequest& request,
                         const fs::path& out_dir) {
  const auto t0 = std::chrono::steady_clock::now();
  const MeshPlan plan = plan_mesh(session, request);
  const int frame = plan.frame;
  const auto& human = session.human(plan.human);
  const PreparedFrame& prepared = plan.prepared;

  // Density grid over the frame's box, a z-slab at a time into marching cubes (METHOD 7).
  const auto bounds = prepared.sample.body.bounds.to(torch::kFloat64).reshape({2, 3});
  const auto grid = mesh::grid_over_bounds(bounds, request.voxel);
  const int64_t plane = grid.height * grid.width;
  const int64_t slab = std::max<int64_t>(1, request.slab_points / std::max<int64_t>(1, plane));
  MeshSummary summary;
  summary.grid = {grid.width, grid.height, grid.depth};
  spdlog::info("mesh: {} frame {} | grid {} x {} x {} at {} mm | threshold {}", human.name(), frame,
               grid.width, grid.height, grid.depth, request.voxel * 1000, request.threshold);
  mesh::MarchingCubes mc(grid.height, grid.width, grid.spec, {request.threshold, kPad, 0.f});
  Progress progress("density", grid.depth, "slice");
  std::vector<torch::Tensor> seen;  // a subsample of the evaluated densities, for the statistics
  render::for_each_chunk(grid.depth, slab, [&](int64_t z0, int64_t z1) {
    const int64_t d = z1 - z0;
    const auto sigma = session.density(prepared, mesh::slab_points(grid, z0, d));
    const auto evaluated = sigma.index({sigma != 0});
    summary.evaluated_points += evaluated.numel();
    seen.push_back(
        evaluated.slice(0, 0, evaluated.numel(), std::max<int64_t>(1, evaluated.numel() / 4096)));
    mc.push(sigma.reshape({d, grid.height, grid.width}));
    progress.advance(d);
  });
  progress.finish();
  summary.mesh = mc.finish();
  // Where the threshold sits in the density the network produced near the body: what a user
  // needs to choose another one (a briefly trained model's density stays low).
  const auto all = torch::cat(seen).to(torch::kFloat64);
  std::string stats = "no point near the body";
  if (all.numel()) {
    const auto q = torch::quantile(all, torch::tensor({0.5, 0.9, 0.99}, torch::kFloat64));
    stats = fmt::format(
        "density near the body: median {:.1f}, 90% {:.1f}, 99% {:.1f}, max {:.1f}; {:.2f}% above "
        "{}",
        q[0].item<double>(), q[1].item<double>(), q[2].item<double>(), all.max().item<double>(),
        100.0 * (all > request.threshold).to(torch::kFloat64).mean().item<double>(),
        request.threshold);
  }
  spdlog::info("mesh: {}", stats);
  if (summary.mesh.num_faces() == 0)
    fail("the density never exceeds the threshold ", request.threshold, " (", stats,
         "): an untrained or collapsed model? try a lower --threshold");

  if (request.colors) {  // the colour branch, looking along the vertex normal from outside
    const auto normals = geometry::vertex_normals(summary.mesh.verts, summary.mesh.faces);
    const auto rgb = session.color(prepared, summary.mesh.verts, -normals);
    summary.mesh.colors = (rgb.clamp(0, 1) * 255).round().to(torch::kUInt8);
  }
  summary.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();

  fs::create_directories(out_dir);
  char stem[160];
  std::snprintf(stem, sizeof stem, "%s_frame%04d", human.name().c_str(), frame);
  summary.ply = out_dir / (std::string(stem) + ".ply");
  // Preview: from the view camera's direction and from its side, upright.
  const auto& cam = human.camera(request.view);
  const auto R = cam.R.to(torch::kFloat64);
  const auto forward = R[2], down = R[1];
  // The header names the world's up (the view camera's), for viewers such as the HTML report's.
  char up[96];
  std::snprintf(up, sizeof up, ", up %.4f %.4f %.4f", -down[0].item<double>(),
                -down[1].item<double>(), -down[2].item<double>());
  mesh::write_ply(
      summary.ply, summary.mesh,
      "TransHuman-C++ mesh of " + human.name() + " frame " + std::to_string(frame) + up);

  const auto side = torch::cross(down, forward, 0);
  std::vector<cv::Mat> views;
  for (const auto& dir : {forward, side}) {
    const auto pc = mesh::frame_mesh(summary.mesh, dir, -down, 512, 512);
    views.push_back(mesh::render_preview(summary.mesh, pc));
  }
  cv::Mat both;
  cv::hconcat(views, both);
  summary.preview = out_dir / (std::string(stem) + "_preview.png");
  video::write_png(summary.preview, both);
  spdlog::info("mesh: {} vertices, {} faces, {} of {} grid points evaluated, {:.1f} s -> {}",
               summary.mesh.num_verts(), summary.mesh.num_faces(), summary.evaluated_points,
               grid.depth * plane, summary.seconds, summary.ply.string());
  return summary;
}

}  // namespace th::inference
