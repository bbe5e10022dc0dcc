// transhuman-bench-bake: baked frames (METHOD 7.1) against the exact renderer, on a trained
// checkpoint and its config's evaluation setting.
//   accuracy  every view of the setting (or the first --items): the exact render and the baked
//             one at each --voxels spacing, scored against the ground truth as transhuman-eval
//             scores (PSNR over the box's rays, SSIM on its crop), and against each other; bake
//             seconds, bricks and size per spacing
//   speed     one frame: the bake's stages, and a baked view at 128, 256 and 512 pixels at 1 and
//             2 threads (median of --repeat renders of an orbit camera)
//   orbit     --orbit-views views at 512x512 (data.ratio=1) through transhuman-render's path:
//             exact, then baked with its bake included
// Usage: transhuman-bench-bake --config configs/demo.yaml --checkpoint
// runs/demo/checkpoints/latest.pt
//          [--voxels 0.04,0.02,0.01] [--sections accuracy speed orbit] [--out
//          bench/results/bake.md]
#include "bake/bake.hpp"

#include <torch/torch.h>

#include <algorithm>
#include <ctime>
#include <map>

#include "app/app.hpp"
#include "common.hpp"
#include "core/config_io.hpp"
#include "core/runtime.hpp"
#include "inference/free_view.hpp"
#include "metrics/metrics.hpp"

namespace fs = std::filesystem;
using namespace th;
using bench::Clock;
using bench::fmt;

namespace {

struct Setup {
  fs::path config, checkpoint;
  std::vector<std::string> overrides;
  Config load(std::vector<std::string> more = {}) const {
    auto all = overrides;
    all.insert(all.end(), more.begin(), more.end());
    return config::load<Config>(config, all);
  }
};

double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v.empty() ? 0.0 : v[v.size() / 2];
}

// A camera of the METHOD 7 orbit around the frame's body.
video::PathCamera orbit_camera(const inference::Session& session,
                               const inference::PreparedFrame& prepared, int width, int height) {
  inference::VideoRequest request;
  request.orbit_views = 36;
  request.width = width;
  request.height = height;
  request.human = prepared.sample.human;
  const auto plan = inference::plan_video(session, request);
  return plan.shots.at(5);
}

struct Scores {
  double psnr_gt = 0, ssim_gt = 0, psnr_exact = 0;
};

Scores score(const torch::Tensor& image, const data::Sample& sample, const torch::Tensor& exact) {
  const auto rays = image.reshape({-1, 3}).index_select(0, sample.ray_pixel);
  Scores s;
  s.psnr_gt = metrics::psnr(rays, sample.ray_rgb);
  s.psnr_exact = metrics::psnr(rays, exact.reshape({-1, 3}).index_select(0, sample.ray_pixel));
  const auto gt = sample.target_image * sample.box_mask.unsqueeze(-1);
  const auto crop = metrics::crop_to_valid(image, gt, sample.box_mask);
  s.ssim_gt = metrics::ssim(crop.pred.to(torch::kFloat64), crop.gt.to(torch::kFloat64));
  return s;
}

void accuracy(const Setup& setup, const std::vector<double>& voxels, int max_items,
              bench::Report& r) {
  const Config c = setup.load();
  const inference::Session session(c, torch::kCPU, setup.checkpoint);
  const auto& data = session.dataset();
  const size_t n = max_items > 0 ? std::min<size_t>(size_t(max_items), data.size()) : data.size();
  // The views grouped by (person, frame): one bake serves a frame's views.
  std::map<std::pair<int, int>, std::vector<int>> frames;
  for (size_t i = 0; i < n; ++i) {
    const auto& it = data.item(i);
    frames[{it.human, it.frame}].push_back(it.target_view);
  }
  r.line("## Accuracy: " + std::to_string(n) + " views of setting '" + c.eval.setting + "' (" +
         std::to_string(frames.size()) + " body frames), " + std::to_string(c.render.samples) +
         " samples per ray");
  r.line("");
  // The exact renders, once.
  struct View {
    data::Sample sample;
    torch::Tensor exact;
    double psnr = 0, ssim = 0;
  };
  std::map<std::pair<int, int>, std::vector<View>> views;
  double exact_seconds = 0;
  for (const auto& [key, cams] : frames)
    for (int v : cams) {
      const auto t0 = Clock::now();
      const auto e = session.evaluate_view(key.first, key.second, v);
      exact_seconds += bench::seconds_since(t0);
      views[key].push_back({data.load_item({key.first, key.second, v}, 0), e.pred, e.psnr, e.ssim});
    }
  double exact_psnr = 0, exact_ssim = 0;
  for (const auto& [key, list] : views)
    for (const auto& v : list) {
      exact_psnr += v.psnr / double(n);
      exact_ssim += v.ssim / double(n);
    }
  r.line(
      "| renderer | bake s per frame (coarse, fine, colour) | points coarse / fine / coloured | "
      "bricks | MiB | view ms | PSNR vs exact | PSNR vs ground truth | SSIM vs ground truth |");
  r.line("|---|---|---|---|---|---|---|---|---|");
  r.line("| exact | - | - | - | - | " + fmt(1e3 * exact_seconds / double(n), 0) + " | - | " +
         fmt(exact_psnr, 2) + " | " + fmt(exact_ssim, 4) + " |");
  for (size_t vi = 0; vi < voxels.size(); ++vi) {
    bake::BakeOptions options;
    options.voxel = voxels[vi];
    {
      std::map<std::string, double> parts;
      double bake_s = 0, mib = 0, view_s = 0, bricks = 0, pc = 0, pf = 0, pcol = 0;
      Scores mean;
      for (const auto& [key, list] : views) {
        const auto prepared =
            session.prepare(key.first, key.second, list.front().sample.target_view);
        bake::BakeReport report;
        const auto t0 = Clock::now();
        const auto baked = bake::bake_frame(session, prepared, options, &report);
        bake_s += bench::seconds_since(t0) / double(views.size());
        for (const auto& [stage, s] : report.seconds) parts[stage] += s / double(views.size());
        mib += baked.bytes() / 1048576.0 / double(views.size());
        bricks += double(baked.stored_bricks()) / double(views.size());
        pc += double(report.coarse_points) / double(views.size());
        pf += double(report.fine_points) / double(views.size());
        pcol += double(report.color_points) / double(views.size());
        bake::MarchOptions march;
        march.samples = c.render.samples;
        march.termination = c.render.termination_transmittance;
        for (const auto& v : list) {
          const auto cam = session.dataset_camera(prepared, v.sample.target_view);
          const auto t1 = Clock::now();
          const auto img =
              bake::render_baked(baked, cam.K, cam.R, cam.T, int(v.sample.target_image.size(1)),
                                 int(v.sample.target_image.size(0)), march);
          view_s += bench::seconds_since(t1) / double(n);
          const auto s = score(img.rgb, v.sample, v.exact);
          mean.psnr_gt += s.psnr_gt / double(n);
          mean.ssim_gt += s.ssim_gt / double(n);
          mean.psnr_exact += s.psnr_exact / double(n);
        }
      }
      r.line("| baked " + fmt(voxels[vi] * 100, 1) + " cm" + " | " + fmt(bake_s, 2) + " (" +
             fmt(parts["coarse"], 2) + ", " + fmt(parts["fine"], 2) + ", " +
             fmt(parts["colour"], 2) + ") | " + fmt(pc, 0) + " / " + fmt(pf, 0) + " / " +
             fmt(pcol, 0) + " | " + fmt(bricks, 0) + " | " + fmt(mib, 1) + " | " +
             fmt(1e3 * view_s, 1) + " | " + fmt(mean.psnr_exact, 2) + " | " + fmt(mean.psnr_gt, 2) +
             " | " + fmt(mean.ssim_gt, 4) + " |");
    }
  }
  r.line("");
}

void speed(const Setup& setup, double voxel, int repeat, bench::Report& r) {
  const Config c = setup.load({"data.ratio=1"});
  const inference::Session session(c, torch::kCPU, setup.checkpoint);
  const auto prepared = session.prepare(0, session.setting_frames(0).front(), 3);
  bake::BakeOptions options;
  options.voxel = voxel;
  bake::BakeReport report;
  runtime::set_threads(2);
  const auto t0 = Clock::now();
  const auto baked = bake::bake_frame(session, prepared, options, &report);
  const double bake_s = bench::seconds_since(t0);
  r.line("## Speed: " + prepared.sample.human + " frame " + std::to_string(prepared.frame) +
         ", voxel " + fmt(voxel * 100, 1) + " cm, " + std::to_string(c.render.samples) +
         " samples per ray");
  r.line("");
  r.line("Bake (2 threads): " + fmt(bake_s, 2) + " s: coarse density " +
         fmt(report.seconds["coarse"], 2) + " s (" + std::to_string(report.coarse_points) +
         " points), fine density " + fmt(report.seconds["fine"], 2) + " s (" +
         std::to_string(report.fine_points) + " points), colour along 6 directions " +
         fmt(report.seconds["colour"], 2) + " s (" + std::to_string(report.color_points) +
         " points), packing " + fmt(report.seconds["pack"], 2) + " s; " +
         std::to_string(baked.stored_bricks()) + " bricks, " + fmt(baked.bytes() / 1048576.0, 1) +
         " MiB.");
  r.line("");
  r.line(
      "| view | threads | median ms | views per second | rays in box | samples looked up | "
      "in stored bricks |");
  r.line("|---|---|---|---|---|---|---|");
  bake::MarchOptions march;
  march.samples = c.render.samples;
  march.termination = c.render.termination_transmittance;
  for (int side : {128, 256, 512})
    for (int threads : {1, 2}) {
      runtime::set_threads(threads);
      const auto cam = orbit_camera(session, prepared, side, side);
      std::vector<double> times;
      bake::MarchStats stats;
      for (int k = 0; k < repeat + 1; ++k) {
        const auto t1 = Clock::now();
        const auto img = bake::render_baked(baked, cam.K, cam.R, cam.T, side, side, march);
        if (k > 0) times.push_back(bench::seconds_since(t1));  // the first warms up
        stats = img.stats;
      }
      const double ms = 1e3 * median(times);
      r.line("| " + std::to_string(side) + "x" + std::to_string(side) + " | " +
             std::to_string(threads) + " | " + fmt(ms, 1) + " | " + fmt(1e3 / ms, 1) + " | " +
             std::to_string(stats.rays) + " | " + std::to_string(stats.samples) + " | " +
             std::to_string(stats.occupied) + " |");
    }
  r.line("");
}

void orbit(const Setup& setup, double voxel, int views, const fs::path& scratch, bench::Report& r) {
  const Config c = setup.load({"data.ratio=1"});
  const inference::Session session(c, torch::kCPU, setup.checkpoint);
  runtime::set_threads(2);
  r.line("## Orbit: " + std::to_string(views) +
         " views at 512x512 (data.ratio=1), transhuman-render's path (PNG frames, video), " +
         std::to_string(c.render.samples) + " samples per ray, 2 threads");
  r.line("");
  r.line("| renderer | seconds | seconds per view | speed-up |");
  r.line("|---|---|---|---|");
  double exact_s = 0;
  for (const bool baked : {false, true}) {
    inference::VideoRequest request;
    request.orbit_views = views;
    request.force = true;
    request.contact_sheet_frames = 0;
    std::unique_ptr<bake::BakedViews> bv;
    if (baked) {
      bake::BakeOptions options;
      options.voxel = voxel;
      bv = std::make_unique<bake::BakedViews>(session, options);
      request.renderer = [&bv](const inference::PreparedFrame& f, const video::PathCamera& cam,
                               int w, int h) { return bv->render(f, cam, w, h); };
      request.renderer_id = bv->id();
    }
    const fs::path dir = scratch / (baked ? "orbit_baked" : "orbit_exact");
    fs::remove_all(dir);
    const auto t0 = Clock::now();  // the bake happens inside, at the first view
    const auto summary = inference::render_video(session, request, dir);
    const double s = bench::seconds_since(t0);
    if (!baked) exact_s = s;
    r.line("| " +
           std::string(baked ? "baked " + fmt(voxel * 100, 1) + " cm, bake included" : "exact") +
           " | " + fmt(s, 1) + " | " + fmt(s / std::max(summary.rendered, 1), 3) + " | " +
           (baked ? fmt(exact_s / s, 1) + "x" : "1x") + " |");
  }
  r.line("");
}

}  // namespace

int main(int argc, char** argv) {
  return app::guarded_main("transhuman-bench-bake", [&]() -> int {
    CLI::App cli{"Baked frames against the exact renderer: accuracy, bake and view speed, orbit."};
    Setup setup;
    std::string voxel_list = "0.04,0.02,0.01";
    std::vector<std::string> sections{"accuracy", "speed", "orbit"};
    fs::path out;
    int items = 0, repeat = 10, orbit_views = 36;
    double speed_voxel = 0.02;
    cli.add_option("--config", setup.config, "the config (the checkpoint's)")->required();
    cli.add_option("--checkpoint", setup.checkpoint, "a trained checkpoint")->required();
    cli.add_option("--voxels", voxel_list, "accuracy: bake spacings in metres, comma-separated");
    cli.add_option("--items", items, "accuracy: the first N views of the setting (0: all)");
    cli.add_option("--speed-voxel", speed_voxel, "speed and orbit: the bake spacing");
    cli.add_option("--repeat", repeat, "speed: renders per size (median)")
        ->check(CLI::Range(1, 1000));
    cli.add_option("--orbit-views", orbit_views, "orbit: views")->check(CLI::Range(1, 360));
    cli.add_option("--sections", sections, "which parts: accuracy speed orbit");
    cli.add_option("--out", out, "append the figures to this markdown file (empty: print only)");
    cli.add_option("overrides", setup.overrides, "config overrides key=value");
    if (const auto rc = app::parse_command_line(cli, argc, argv)) return *rc;
    std::vector<double> voxels;
    std::stringstream ss(voxel_list);
    for (std::string part; std::getline(ss, part, ',');) voxels.push_back(std::stod(part));
    if (voxels.empty()) fail("--voxels: give at least one spacing");
    runtime::keep_freed_memory();
    runtime::set_threads(2);
    bench::Report r;
    const std::time_t now = std::time(nullptr);
    char date[32];
    std::strftime(date, sizeof date, "%Y-%m-%d %H:%M UTC", std::gmtime(&now));
    r.line("# Baked frames (" + std::string(date) + ")");
    r.line("");
    r.line("Config " + setup.config.string() + ", checkpoint " + setup.checkpoint.string() +
           "; commit " + bench::git_commit() + "; LibTorch " + std::string(TORCH_VERSION) +
           "; processor " + bench::cpu_model() + ", " +
           std::to_string(std::thread::hardware_concurrency()) + " cores, load average at start " +
           bench::load_average() + ".");
    r.line("");
    const fs::path scratch =
        fs::temp_directory_path() / ("transhuman-bench-bake-" + std::to_string(::getpid()));
    for (const auto& s : sections) {
      if (s == "accuracy")
        accuracy(setup, voxels, items, r);
      else if (s == "speed")
        speed(setup, speed_voxel, repeat, r);
      else if (s == "orbit")
        orbit(setup, speed_voxel, orbit_views, scratch, r);
      else
        fail("--sections: unknown section '", s, "' (accuracy, speed, orbit)");
    }
    fs::remove_all(scratch);
    r.line("Load average at the end: " + bench::load_average() + ".");
    if (!out.empty()) {
      std::ofstream f(out, std::ios::app);
      f << r.md.str() << "\n";
    }
    return 0;
  });
}
