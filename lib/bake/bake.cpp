#include "bake/bake.hpp"

#include <fmt/format.h>
#include <fmt/ranges.h>
#include <torch/torch.h>

#include <chrono>
#include <cmath>

#include "core/error.hpp"

namespace th::bake {
namespace F = torch::nn::functional;
namespace fs = std::filesystem;
namespace {

using Clock = std::chrono::steady_clock;

double since(Clock::time_point start) {
  return std::chrono::duration<double>(Clock::now() - start).count();
}

// World positions of lattice points `index` (M, 3) int64 of spacing `step` from `origin`.
torch::Tensor positions(const torch::Tensor& index, const std::array<double, 3>& origin,
                        double step) {
  return index.to(torch::kFloat64) * step +
         torch::tensor({origin[0], origin[1], origin[2]}, torch::kFloat64);
}

// (X, Y, Z) -> (1, 1, X, Y, Z) float, and back.
torch::Tensor volume(const torch::Tensor& t) {
  return t.to(torch::kFloat32).unsqueeze(0).unsqueeze(0);
}
torch::Tensor unvolume(const torch::Tensor& t) { return t.squeeze(0).squeeze(0); }

// The lattice over a frame's box: it covers the box as the rays see it (padded by 0.01,
// data::near_far), in whole coarse cells.
struct Lattice {
  std::array<double, 3> origin{};
  std::array<int64_t, 3> coarse_cells{}, cells{};
};

Lattice lattice_over(const std::array<double, 6>& box, const BakeOptions& options) {
  const double h = options.voxel;
  Lattice l;
  for (int a = 0; a < 3; ++a) {
    l.origin[a] = box[a] - 0.01;
    const double extent = box[3 + a] - box[a] + 0.02;
    l.coarse_cells[a] =
        std::max<int64_t>(1, int64_t(std::ceil(extent / (h * options.coarse) - 1e-9)));
    l.cells[a] = l.coarse_cells[a] * options.coarse;
    if (l.cells[a] > 4096)
      fail("--bake-voxel ", h, " m: the frame's box needs ", l.cells[a],
           " cells along an axis, more than 4096; choose a larger voxel");
  }
  return l;
}

// Max over a (2r+1)^3 neighbourhood, same size.
torch::Tensor dilate(const torch::Tensor& mask, int r) {
  return unvolume(F::max_pool3d(volume(mask),
                                F::MaxPool3dFuncOptions(2 * r + 1).stride(1).padding(r))) > 0;
}

}  // namespace

double BakeReport::total_seconds() const {
  double s = 0;
  for (const auto& kv : seconds) s += kv.second;
  return s;
}

void check_options(const BakeOptions& o) {
  if (!(std::isfinite(o.voxel) && o.voxel >= 0.001 && o.voxel <= 0.2))
    fail("bake voxel = ", o.voxel, " m: must be in [0.001, 0.2] metres");
  if (o.coarse < 1 || o.coarse > 8) fail("bake coarse factor = ", o.coarse, ": must be in [1, 8]");
  if (o.brick < 2 || o.brick > 32) fail("bake brick = ", o.brick, ": must be in [2, 32] cells");
  for (const auto& eye : o.eyes)
    if (!(std::isfinite(eye[0]) && std::isfinite(eye[1]) && std::isfinite(eye[2])))
      fail("bake eye (", eye[0], ", ", eye[1], ", ", eye[2], "): a camera centre must be finite");
}

std::array<double, 6> bake_box(const torch::Tensor& bounds) {
  TORCH_CHECK(bounds.numel() == 6, "bake_box: bounds must be (2, 3)");
  const auto b = bounds.to(torch::kFloat64).contiguous().view({2, 3});
  std::array<double, 6> box{};
  for (int a = 0; a < 3; ++a) {
    box[a] = b[0][a].item<double>();
    box[3 + a] = b[1][a].item<double>();
  }
  return box;
}

resources::Estimate bake_estimate(const std::array<double, 6>& box, const BakeOptions& options,
                                  const inference::Session& session, const std::string& what) {
  check_options(options);
  const Lattice l = lattice_over(box, options);
  double points = 1, coarse = 1, padded = 1;  // lattice points: fine, coarse, padded to bricks
  for (int a = 0; a < 3; ++a) {
    points *= double(l.cells[a] + 1);
    coarse *= double(l.coarse_cells[a] + 1);
    padded *= double((l.cells[a] + options.brick - 1) / options.brick * options.brick + 1);
  }
  // Dense grids bake_frame holds at its peak (the packing): masks (1 byte each: refined cells,
  // refined points, positive, coloured), the fine density (4), the padded density (4) and its
  // temporary (5), colour rows over the lattice and the padded one (8 + 8).
  const double dense = points * (4 * 1 + 4 + 8) + padded * (4 + 5 + 8);
  // Point lists near the body: fine points (24 bytes of index), coloured points (index,
  // position, colour, row: 68) and the stored bricks' points while they are packed (about 80).
  // On the demo checkpoint 30% of the lattice is fine or coloured and 60% lies in stored bricks
  // (bench/results/bake.md, 1 cm): taken as 60% and all of the padded lattice.
  const double near = 0.6 * points;
  // A colour set per eye adds 12 bytes per coloured and per packed point.
  const double sets = double(std::max<size_t>(1, options.eyes.size()));
  const double sparse = near * 24 + near * (68 + 12 * (sets - 1)) + padded * (80 + 12 * (sets - 1));
  resources::Estimate e;
  e.what = fmt::format("bake of {} at --bake-voxel {} m (lattice {} x {} x {})", what,
                       options.voxel, l.cells[0] + 1, l.cells[1] + 1, l.cells[2] + 1);
  e.bytes = dense + sparse +
            double(session.config().render.chunk_points) * resources::kBytesPerChunkPoint;
  e.samples = coarse + near + 2 * near;  // a coloured point costs about two
  e.threads = session.device().is_cpu() ? torch::get_num_threads() : 0;
  return e;
}

void check_bake_memory(const std::array<double, 6>& box, const BakeOptions& options,
                       const inference::Session& session, const std::string& what) {
  resources::check(bake_estimate(box, options, session, what), session.config().max_memory_gb);
}

BakedFrame bake_frame(const inference::Session& session, const inference::PreparedFrame& frame,
                      const BakeOptions& options, BakeReport* report,
                      const BakeProgress& progress) {
  check_options(options);
  const auto frame_box = bake_box(frame.sample.body.bounds);
  check_bake_memory(frame_box, options, session,
                    fmt::format("{} frame {}", frame.sample.human, frame.sample.frame));
  torch::NoGradGuard no_grad;
  BakeReport unused;
  BakeReport& rep = report ? *report : unused;
  const double h = options.voxel;
  const int f = options.coarse;

  BakedFrame out;
  out.human = frame.sample.human;
  out.frame = frame.sample.frame;
  out.checkpoint = session.checkpoint_id();
  out.reference_views = frame.sample.reference_views;
  out.voxel = h;
  out.brick = options.brick;
  out.cull_distance = session.config().render.cull_distance;
  out.box = frame_box;
  const Lattice lattice = lattice_over(out.box, options);
  const auto coarse_cells = lattice.coarse_cells;
  out.origin = lattice.origin;
  out.cells = lattice.cells;

  // The network's work in chunks, with progress over the three stages' points.
  const int64_t chunk = std::max<int64_t>(1024, session.config().render.chunk_points);
  double done = 0, planned = 1;
  auto tick = [&](int64_t n) {
    done += double(n);
    if (progress) progress(std::min(1.0, done / planned));
  };
  auto density = [&](const torch::Tensor& pts) {
    auto sigma = torch::zeros({pts.size(0)}, torch::kFloat32);
    for (int64_t b = 0; b < pts.size(0); b += chunk) {
      const int64_t e = std::min(pts.size(0), b + chunk);
      sigma.slice(0, b, e).copy_(session.density(frame, pts.slice(0, b, e)));
      tick(e - b);
    }
    return sigma;
  };

  // 1. Coarse density.
  auto start = Clock::now();
  const auto grid_index = [](const std::array<int64_t, 3>& n) {
    return torch::stack(torch::meshgrid({torch::arange(n[0] + 1), torch::arange(n[1] + 1),
                                         torch::arange(n[2] + 1)},
                                        "ij"),
                        -1)
        .reshape({-1, 3});
  };
  const auto coarse_index = grid_index(coarse_cells);
  rep.coarse_points = coarse_index.size(0);
  planned = double(rep.coarse_points) * 1.5;  // until the fine and colour work is known
  const auto coarse = density(positions(coarse_index, out.origin, h * f))
                          .view({coarse_cells[0] + 1, coarse_cells[1] + 1, coarse_cells[2] + 1});
  rep.seconds["coarse"] = since(start);

  // 2. Fine density where the surface passes.
  start = Clock::now();
  const auto positive = volume(coarse > 0);
  const auto any = F::max_pool3d(positive, F::MaxPool3dFuncOptions(2).stride(1));
  const auto all = -F::max_pool3d(-positive, F::MaxPool3dFuncOptions(2).stride(1));
  auto refine = unvolume(any - all) > 0;  // coarse cells, (cx, cy, cz)
  refine = dilate(refine, 1);
  for (int a = 0; a < 3; ++a) refine = refine.repeat_interleave(f, a);  // fine cells
  // A lattice point is refined when a cell it touches is.
  const auto fine_mask =
      unvolume(F::max_pool3d(volume(refine), F::MaxPool3dFuncOptions(2).stride(1).padding(1))) > 0;
  auto fine = unvolume(F::interpolate(volume(coarse),
                                      F::InterpolateFuncOptions()
                                          .size(std::vector<int64_t>{
                                              out.cells[0] + 1, out.cells[1] + 1, out.cells[2] + 1})
                                          .mode(torch::kTrilinear)
                                          .align_corners(true)))
                  .contiguous();
  const auto fine_index = fine_mask.nonzero();
  rep.fine_points = fine_index.size(0);
  planned = done + double(rep.fine_points) + 0.5 * double(rep.fine_points);
  const auto flat = [&](const torch::Tensor& index) {
    return (index.select(1, 0) * (out.cells[1] + 1) + index.select(1, 1)) * (out.cells[2] + 1) +
           index.select(1, 2);
  };
  fine.view({-1}).index_put_({flat(fine_index)}, density(positions(fine_index, out.origin, h)));
  rep.seconds["fine"] = since(start);

  // 3. Colour at the points with positive density, the only ones the march weighs (METHOD 7.1):
  // along the six axis directions, or from each eye.
  start = Clock::now();
  out.eyes = options.eyes;
  const int sets = out.color_sets();
  const auto color_index = (fine > 0).nonzero();
  rep.color_points = color_index.size(0);
  planned = done + 2.0 * double(rep.color_points);  // a colour point costs about two
  const auto directions = torch::tensor({1.0, 0.0, 0.0, -1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, -1.0,
                                         0.0, 0.0, 0.0, 1.0, 0.0, 0.0, -1.0},
                                        torch::kFloat32)
                              .view({6, 3});
  const auto color_pts = positions(color_index, out.origin, h);
  auto colors = torch::zeros({rep.color_points, sets * kColorDims}, torch::kFloat32);
  const auto eyes = [&] {
    std::vector<double> flat_eyes;
    for (const auto& eye : out.eyes) flat_eyes.insert(flat_eyes.end(), eye.begin(), eye.end());
    return torch::tensor(flat_eyes, torch::kFloat64).view({-1, 1, 3});
  }();
  const auto color_flat = flat(color_index);
  for (int64_t b = 0; b < rep.color_points; b += chunk) {
    const int64_t e = std::min(rep.color_points, b + chunk);
    const auto pts = color_pts.slice(0, b, e);
    // The six axis directions' mean, or from each eye: (K, M, 3) directions, (M, K x 3) colours.
    const auto seen = session.colors_along(
        frame, pts, out.eyes.empty() ? directions : (pts.unsqueeze(0) - eyes).to(torch::kFloat32));
    colors.slice(0, b, e).copy_(
        out.eyes.empty() ? seen.rgb.mean(0)
                         : seen.rgb.permute({1, 0, 2}).reshape({e - b, sets * kColorDims}));
    // The density of these points, asked of the network with their colour: exact values where
    // step 2 interpolated.
    fine.view({-1}).index_put_({color_flat.slice(0, b, e)}, seen.sigma);
    tick(2 * (e - b));
  }
  rep.seconds["colour"] = since(start);

  // 4. The bricks with positive density, each with its (brick + 1)^3 lattice points.
  start = Clock::now();
  const int B = options.brick;
  const auto nb = out.bricks();
  const int64_t P = B + 1;
  // Lattice padded with zeros to whole bricks.
  auto padded = torch::zeros({nb[0] * B + 1, nb[1] * B + 1, nb[2] * B + 1}, torch::kFloat32);
  padded.slice(0, 0, out.cells[0] + 1)
      .slice(1, 0, out.cells[1] + 1)
      .slice(2, 0, out.cells[2] + 1)
      .copy_(fine);
  auto color_dense = torch::full(fine.sizes(), -1, torch::kInt64);
  color_dense.view({-1}).index_put_({color_flat}, torch::arange(rep.color_points));
  auto color_row = torch::full(padded.sizes(), -1, torch::kInt64);
  color_row.slice(0, 0, out.cells[0] + 1)
      .slice(1, 0, out.cells[1] + 1)
      .slice(2, 0, out.cells[2] + 1)
      .copy_(color_dense);
  const auto occupied =
      unvolume(F::max_pool3d(volume(padded > 0), F::MaxPool3dFuncOptions(P).stride(B))) > 0;
  const auto stored = occupied.flatten().nonzero().flatten();
  const int64_t slots = stored.size(0);
  out.slot.assign(size_t(nb[0] * nb[1] * nb[2]), -1);
  const auto stored_acc = stored.accessor<int64_t, 1>();
  for (int64_t s = 0; s < slots; ++s) out.slot[size_t(stored_acc[s])] = int32_t(s);
  // Lattice indices of every stored brick's points: brick origin + local offset.
  const auto brick_origin =
      torch::stack({torch::div(stored, nb[1] * nb[2], "floor"),
                    torch::div(stored, nb[2], "floor").remainder(nb[1]), stored.remainder(nb[2])},
                   1) *
      B;
  const auto offsets = grid_index({B, B, B});  // (P^3, 3), x slowest
  const auto index = (brick_origin.unsqueeze(1) + offsets.unsqueeze(0)).reshape({-1, 3});
  const auto padded_flat =
      (index.select(1, 0) * padded.size(1) + index.select(1, 1)) * padded.size(2) +
      index.select(1, 2);
  const auto density_values = padded.view({-1}).index_select(0, padded_flat).contiguous();
  const auto rows = color_row.view({-1}).index_select(0, padded_flat);
  const auto color_values =
      torch::where(rows.ge(0).unsqueeze(1), colors.index_select(0, rows.clamp_min(0)),
                   torch::zeros({1, sets * kColorDims}, torch::kFloat32))
          .contiguous();
  out.density.assign(density_values.template data_ptr<float>(),
                     density_values.template data_ptr<float>() + density_values.numel());
  out.color.assign(color_values.template data_ptr<float>(),
                   color_values.template data_ptr<float>() + color_values.numel());
  TORCH_CHECK(int64_t(out.density.size()) == slots * P * P * P, "bake: brick packing");
  rep.seconds["pack"] = since(start);
  if (progress) progress(1.0);
  return out;
}

BakedViews::BakedViews(const inference::Session& session, const BakeOptions& options)
    : session_(session), options_(options) {
  check_options(options);
  march_.samples = session.config().render.samples;
  march_.termination = session.config().render.termination_transmittance;
}

void BakedViews::use(BakedFrame baked, const inference::PreparedFrame& frame) {
  const std::string where = "baked frame '" + baked.file + "'";
  auto refuse = [&](const std::string& what, const auto& file, const auto& now) {
    fail(where, " is a bake of ", what, " ", file, ", not ", now,
         ": bake this one with --baked (and --bake-out to keep it)");
  };
  if (baked.human != frame.sample.human) refuse("person", baked.human, frame.sample.human);
  if (baked.frame != frame.sample.frame)
    refuse("frame", baked.frame, std::to_string(frame.sample.frame) + " (--frames)");
  if (baked.reference_views != frame.sample.reference_views)
    refuse("reference views", fmt::format("[{}]", fmt::join(baked.reference_views, ", ")),
           fmt::format("[{}]", fmt::join(frame.sample.reference_views, ", ")));
  if (baked.checkpoint != session_.checkpoint_id())
    fail(where, " was made by checkpoint ", baked.checkpoint, ", not by ", session_.checkpoint_id(),
         ": bake it again");
  if (baked.cull_distance != session_.config().render.cull_distance)
    fail(where, " was made with render.cull_distance ", baked.cull_distance, ", not ",
         session_.config().render.cull_distance);
  baked_ = std::move(baked);
  kept_ = true;
  from_file_ = true;
}

const BakedFrame& BakedViews::bake(const inference::PreparedFrame& frame) {
  if (kept_ && baked_.human == frame.sample.human && baked_.frame == frame.sample.frame &&
      baked_.reference_views == frame.sample.reference_views)
    return baked_;
  report_ = {};
  baked_ = bake_frame(session_, frame, options_, &report_);
  kept_ = true;
  from_file_ = false;
  return baked_;
}

torch::Tensor BakedViews::render(const inference::PreparedFrame& frame,
                                 const video::PathCamera& camera, int width, int height) {
  return render_baked(bake(frame), camera.K, camera.R, camera.T, width, height, march_).rgb;
}

std::string BakedViews::id() const { return "baked"; }

std::vector<std::pair<std::string, std::string>> BakedViews::request_keys() const {
  if (from_file_)
    return {{"bake.source", fs::absolute(baked_.file).lexically_normal().string()},
            {"bake.file", baked_.digest},
            {"bake.voxel", fmt::format("{}", baked_.voxel)},
            {"bake.brick", std::to_string(baked_.brick)}};
  return {{"bake.source", "this run"},
          {"bake.voxel", fmt::format("{}", options_.voxel)},
          {"bake.coarse", std::to_string(options_.coarse)},
          {"bake.brick", std::to_string(options_.brick)}};
}

std::string renderer_label(ViewRenderer renderer, double voxel) {
  return renderer == ViewRenderer::baked ? fmt::format("baked {:g} cm", voxel * 100) : "exact";
}

SampleBakes::SampleBakes(const inference::Session& session, const BakeOptions& options)
    : session_(session), options_(options) {
  check_options(options);
  march_.samples = session.config().render.samples;
  march_.termination = session.config().render.termination_transmittance;
}

std::array<double, 3> camera_centre(const torch::Tensor& R, const torch::Tensor& T) {
  const auto c =
      -torch::mv(R.to(torch::kFloat64).reshape({3, 3}).t(), T.to(torch::kFloat64).reshape({3}));
  return {c[0].item<double>(), c[1].item<double>(), c[2].item<double>()};
}

SampleBakes::View SampleBakes::render(const data::Sample& sample,
                                      const std::vector<std::array<double, 3>>& frame_eyes) {
  View view;
  const auto eye = camera_centre(sample.R, sample.T);
  // Which of a list of eyes is this sample's camera (float32 cameras: within 0.1 mm).
  const auto find = [&](const std::vector<std::array<double, 3>>& eyes) {
    for (size_t k = 0; k < eyes.size(); ++k)
      if (std::abs(eyes[k][0] - eye[0]) + std::abs(eyes[k][1] - eye[1]) +
              std::abs(eyes[k][2] - eye[2]) <
          1e-4)
        return int(k);
    return -1;
  };
  if (!baked_ || baked_->human != sample.human || baked_->frame != sample.frame ||
      baked_->reference_views != sample.reference_views || find(baked_->eyes) < 0) {
    baked_.reset();  // the last frame's grid goes before the next is made
    const auto t0 = Clock::now();
    const auto prepared = session_.prepare(sample);
    BakeOptions options = options_;
    options.eyes = frame_eyes;
    if (find(options.eyes) < 0) options.eyes.push_back(eye);
    baked_ = bake_frame(session_, prepared, options);
    view.bake_seconds = since(t0);
    ++bakes_;
  }
  MarchOptions march = march_;
  march.color_set = find(baked_->eyes);
  const auto t0 = Clock::now();
  const auto image =
      render_baked(*baked_, sample.K.to(torch::kFloat64), sample.R.to(torch::kFloat64),
                   sample.T.to(torch::kFloat64).reshape({3, 1}), int(sample.target_image.size(1)),
                   int(sample.target_image.size(0)), march);
  const auto pixel = sample.ray_pixel.to(torch::kCPU);
  view.ray_rgb = image.rgb.reshape({-1, 3}).index_select(0, pixel);
  view.ray_acc = image.acc.reshape({-1}).index_select(0, pixel);
  view.march_seconds = since(t0);
  view.stats = image.stats;
  ++views_;
  return view;
}

}  // namespace th::bake
