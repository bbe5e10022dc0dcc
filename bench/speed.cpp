// What a user waits for (issue 15), the exact and the default paths side by side in one run,
// on a trained checkpoint and the dataset of its config:
//   view   one test view at data.ratio 1 (512 x 512 on the synthetic data), 64 and 16 samples per
//          ray: seconds to prepare the frame and to render it, points evaluated, peak memory, and
//          the largest per-ray difference of the default image from the exact one;
//   orbit  36 orbit views of one frame at that size (transhuman-render's path);
//   train  seconds per training step at the config (after a warm-up);
//   eval   the evaluation of the config's setting, every image (transhuman-eval's path).
// "exact": render.termination_transmittance=0, eval.reuse_frames=false, i.e. what main did
// before these shortcuts; "default": the config as it is. The figures are appended, with the
// date, the machine and its load, to --out.
//   transhuman-bench-speed --config configs/demo.yaml --checkpoint runs/demo/checkpoints/latest.pt
//                          [--out bench/results/speed.md] [--sections view orbit train eval]
#include <CLI/CLI.hpp>
#include <torch/torch.h>

#include <unistd.h>

#include <ctime>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <map>
#include <thread>

#include "body/smpl.hpp"
#include "common.hpp"
#include "core/config_io.hpp"
#include "core/runtime.hpp"
#include "data/dataset.hpp"
#include "eval/evaluator.hpp"
#include "inference/free_view.hpp"
#include "inference/session.hpp"
#include "model/transhuman.hpp"
#include "pipeline/checkpoint.hpp"
#include "pipeline/pipeline.hpp"
#include "train/trainer.hpp"

using namespace th;
using bench::Clock;
using bench::fmt;
using bench::seconds_since;
namespace fs = std::filesystem;

namespace {

const std::vector<std::string> kExact{"render.termination_transmittance=0", "eval.reuse_frames=false"};

struct Setup {
  fs::path config, checkpoint, scratch;
  std::vector<std::string> overrides;
  Config load(std::vector<std::string> more = {}, bool exact = false) const {
    auto all = overrides;
    if (exact) all.insert(all.end(), kExact.begin(), kExact.end());
    all.insert(all.end(), more.begin(), more.end());
    return config::load<Config>(config, all);
  }
};

std::string ratio(double slow, double fast) { return fmt(slow / std::max(fast, 1e-9), 2) + "x"; }

void view_section(const Setup& setup, bench::Report& r) {
  const Config base = setup.load({"data.ratio=1"});
  const auto smpl = data::load_body_model(base.data);
  const data::Dataset dataset(base.data, base.eval.setting, data::Dataset::Mode::Test, smpl);
  model::TransHuman net(base.model, base.render.cull_distance);
  pipeline::load_weights(*net, setup.checkpoint, base.eval.model_mismatch == "warn");
  net->eval();
  pipeline::Tokens tokens(base.model.grouping, smpl->v_template);
  const auto sample = dataset.load(0, 0);
  const auto inputs = pipeline::frame_inputs(sample, smpl->v_template, tokens.labels(sample.body), torch::kCPU);
  const auto rays = pipeline::sample_rays(sample, torch::kCPU);
  torch::NoGradGuard no_grad;
  auto t0 = Clock::now();
  const auto cache = net->prepare(inputs);
  const double prepare = seconds_since(t0);
  r.line("## One test view: " + sample.human + " frame " + std::to_string(sample.frame) + " view " +
         std::to_string(sample.target_view) + ", " + std::to_string(sample.target_image.size(1)) + "x" +
         std::to_string(sample.target_image.size(0)) + ", " + std::to_string(rays.size()) + " in-box rays");
  r.line("");
  r.line("Frame preparation (encoder, TransHE, readouts; once per frame): " + fmt(prepare, 2) + " s.");
  r.line("");
  r.line("| samples | path | render s | view s (with preparation) | points evaluated | colour points | skipped by "
         "termination | peak MiB tensors | max abs rgb diff | max abs acc diff | speed-up |");
  r.line("|---|---|---|---|---|---|---|---|---|---|---|");
  for (int samples : {64, 16}) {
    render::RenderResult exact;
    double exact_sec = 0;
    for (bool fast : {false, true}) {
      auto rc = base.render;
      rc.samples = samples;
      if (!fast) rc.termination_transmittance = 0;
      bench::PeakMemory mem;
      t0 = Clock::now();
      const auto img = model::render_rays(*net, cache, rays, rc);
      const double sec = seconds_since(t0);
      if (!fast) {
        exact = img;
        exact_sec = sec;
      }
      const auto& st = img.stats;
      const double drgb = (img.rgb - exact.rgb).abs().max().item<double>();
      const double dacc = (img.acc - exact.acc).abs().max().item<double>();
      r.line("| " + std::to_string(samples) + " | " + (fast ? "default" : "exact") + " | " + fmt(sec, 2) + " | " +
             fmt(sec + prepare, 2) + " | " + std::to_string(st.density_points) + " | " +
             std::to_string(st.color_points) + " | " + std::to_string(st.terminated_points) + " | " +
             fmt(mem.tensor_mib(), 0) + " | " + fmt(drgb * 1e3, 3) + "e-3 | " + fmt(dacc * 1e3, 3) + "e-3 | " +
             ratio(exact_sec, sec) + " |");
    }
  }
  r.line("");
}

void orbit_section(const Setup& setup, bench::Report& r, int views) {
  r.line("## Orbit: " + std::to_string(views) + " views of one frame at data.ratio 1 (transhuman-render)");
  r.line("");
  r.line("| path | seconds | seconds per view | speed-up |");
  r.line("|---|---|---|---|");
  double exact_sec = 0;
  for (bool fast : {false, true}) {
    const Config c = setup.load({"data.ratio=1"}, !fast);
    const inference::Session session(c, torch::kCPU, setup.checkpoint);
    inference::VideoRequest request;
    request.orbit_views = views;
    request.force = true;
    request.contact_sheet_frames = 0;
    const auto t0 = Clock::now();
    const auto summary = inference::render_video(session, request, setup.scratch / (fast ? "orbit_fast" : "orbit_exact"));
    const double sec = seconds_since(t0);
    if (!fast) exact_sec = sec;
    r.line(std::string("| ") + (fast ? "default" : "exact") + " | " + fmt(sec, 1) + " | " +
           fmt(sec / std::max(summary.rendered, 1), 2) + " | " + ratio(exact_sec, sec) + " |");
  }
  r.line("");
}

// Mean time_per_step of the last metrics line (steps after the first `steps` of warm-up).
double step_seconds(const fs::path& metrics) {
  std::ifstream in(metrics);
  std::string line, last;
  while (std::getline(in, line))
    if (!line.empty()) last = line;
  const auto at = last.find("\"time_per_step\": ");
  if (at == std::string::npos) throw std::runtime_error("no time_per_step in " + metrics.string());
  return std::stod(last.substr(at + 17));
}

void train_section(const Setup& setup, bench::Report& r, int steps) {
  r.line("## Training steps at the config (" + std::to_string(steps) + " steps after " + std::to_string(steps) +
         " of warm-up)");
  r.line("");
  r.line("| path | seconds per step | steps per second | speed-up |");
  r.line("|---|---|---|---|");
  const std::vector<std::string> quiet{"train.log_every_steps=" + std::to_string(steps), "train.val_views=0",
                                       "train.save_every_epochs=0"};
  const Config c = setup.load(quiet);
  const fs::path dir = setup.scratch / "train";
  fs::remove_all(dir);
  train::train(c, torch::kCPU, {dir, false, 2 * steps});
  const double sec = step_seconds(dir / "metrics.jsonl");
  r.line("| default | " + fmt(sec, 3) + " | " + fmt(1 / sec, 3) + " | 1.00x |");
  r.line("");
}

void eval_section(const Setup& setup, bench::Report& r) {
  const Config probe = setup.load();
  r.line("## Evaluation: setting " + probe.eval.setting + " at the config (transhuman-eval)");
  r.line("");
  r.line("| path | images | seconds | seconds per image | PSNR | SSIM | points evaluated | largest per-image PSNR "
         "difference | speed-up |");
  r.line("|---|---|---|---|---|---|---|---|---|");
  eval::EvalSummary exact;
  double exact_sec = 0;
  for (bool fast : {false, true}) {
    const Config c = setup.load({"eval.save_images=false"}, !fast);
    const fs::path dir = setup.scratch / (fast ? "eval_fast" : "eval_exact");
    fs::remove_all(dir);
    fs::create_directories(dir);
    const auto t0 = Clock::now();
    const auto s = eval::evaluate(c, torch::kCPU, setup.checkpoint, dir);
    const double sec = seconds_since(t0);
    if (!fast) {
      exact = s;
      exact_sec = sec;
    }
    int64_t points = 0;
    double worst = 0;
    for (size_t i = 0; i < s.per_image.size(); ++i) {
      points += s.per_image[i].evaluated_points;
      worst = std::max(worst, std::abs(s.per_image[i].psnr - exact.per_image[i].psnr));
    }
    r.line(std::string("| ") + (fast ? "default" : "exact") + " | " + std::to_string(s.images) + " | " + fmt(sec, 1) +
           " | " + fmt(sec / std::max(s.images, 1), 3) + " | " + fmt(s.psnr, 3) + " | " + fmt(s.ssim, 4) + " | " +
           std::to_string(points) + " | " + fmt(worst, 4) + " dB | " + ratio(exact_sec, sec) + " |");
  }
  r.line("");
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App cli{"TransHuman speed benchmark: exact and default paths side by side (issue 15)"};
  Setup setup;
  int threads = 0, orbit_views = 36, train_steps = 10;
  fs::path out = "bench/results/speed.md";
  std::vector<std::string> sections{"view", "orbit", "train", "eval"};
  cli.add_option("--config", setup.config, "the config (the checkpoint's)")->required();
  cli.add_option("--checkpoint", setup.checkpoint, "a trained checkpoint")->required();
  cli.add_option("--out", out, "append the figures to this markdown file");
  cli.add_option("--sections", sections, "which parts to run: view orbit train eval");
  cli.add_option("--orbit-views", orbit_views, "orbit views");
  cli.add_option("--train-steps", train_steps, "training steps measured (after as many of warm-up)");
  cli.add_option("--threads", threads, "LibTorch threads (0: one per core)");
  cli.add_option("--scratch", setup.scratch, "scratch folder (default: a temporary one, removed at the end)");
  cli.add_option("overrides", setup.overrides, "config overrides key=value");
  CLI11_PARSE(cli, argc, argv);
  const bool own_scratch = setup.scratch.empty();
  if (own_scratch) setup.scratch = fs::temp_directory_path() / ("transhuman-bench-speed-" + std::to_string(::getpid()));
  fs::create_directories(setup.scratch);
  setup.overrides.push_back("threads=" + std::to_string(threads));
  const int nthreads = runtime::set_threads(threads);

  bench::Report r;
  const std::time_t now = std::time(nullptr);
  char date[32];
  std::strftime(date, sizeof date, "%Y-%m-%d %H:%M UTC", std::gmtime(&now));
  r.line("# Speed: exact and default paths (" + std::string(date) + ")");
  r.line("");
  r.line("Config " + setup.config.string() + ", checkpoint " + setup.checkpoint.string() + "; LibTorch " +
         std::string(TORCH_VERSION) + ", " + std::to_string(nthreads) + " threads, BLAS " + runtime::detect_blas().name +
         "; " + std::to_string(std::thread::hardware_concurrency()) + " cores, load average at start " +
         bench::load_average() + ".");
  r.line("Exact: " + std::string("render.termination_transmittance=0, eval.reuse_frames=false") +
         " (main before issue 15). Default: the config as it is.");
  r.line("");
  try {
    for (const auto& s : sections) {
      if (s == "view") view_section(setup, r);
      else if (s == "orbit") orbit_section(setup, r, orbit_views);
      else if (s == "train") train_section(setup, r, train_steps);
      else if (s == "eval") eval_section(setup, r);
      else throw std::runtime_error("unknown section '" + s + "' (view, orbit, train, eval)");
    }
  } catch (const std::exception& e) {
    std::cerr << "transhuman-bench-speed: error: " << e.what() << std::endl;
    if (own_scratch) fs::remove_all(setup.scratch);
    return 1;
  }
  r.line("Load average at the end: " + bench::load_average() + ".");
  r.line("");
  if (own_scratch) fs::remove_all(setup.scratch);
  if (!out.empty()) {
    std::ofstream f(out, std::ios::app);
    f << r.md.str();
    std::cout << "appended to " << out.string() << std::endl;
  }
  return 0;
}
