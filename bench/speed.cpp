// What a user waits for, several paths side by side in one run, on a trained checkpoint and the
// dataset of its config:
//   view   one test view at data.ratio 1 (512 x 512 on the synthetic data), 64 and 16 samples per
//          ray: seconds to prepare the frame and to render it, points evaluated, peak memory, and
//          the largest per-ray difference of the default image from the exact one;
//   orbit  36 orbit views of one frame at that size (transhuman-render's path);
//   train  seconds per training step at the config (after a warm-up);
//   eval   the evaluation of the config's setting, every image (transhuman-eval's path).
// Paths (--paths, the first is the reference of the speed-ups and differences):
// "exact": the speed switches off (render.termination_transmittance=0, eval.reuse_frames=false,
// render.train_recompute=always), fp32 products through BLAS and glibc's malloc defaults, except
// for the changes that have no switch because they only make the same arithmetic faster or
// round it otherwise (the vectorised attention and DPaRF loops, colour without a row copy, the
// readout windows, the project's kernels compiled with OpenMP).
// "blas": the config with precision=fp32 and fp32 products through BLAS.
// "fp32", "bf16", "auto": the config with that precision (fp32 products as the config says).
// "default": the config as it is.
// Every path runs in a process of its own; with --repeat N the paths alternate N times. The
// figures are appended, with the date, the machine and its load, to --out.
//   transhuman-bench-speed --config configs/demo.yaml --checkpoint runs/demo/checkpoints/latest.pt
//                          [--out bench/results/speed.md] [--sections view orbit train eval]
//                          [--paths blas fp32 bf16] [--repeat 2]
#include <torch/torch.h>
#include <unistd.h>

#include <CLI/CLI.hpp>
#include <cmath>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <iostream>
#include <limits>
#include <map>
#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <thread>

#include "app/app.hpp"
#include "body/smpl.hpp"
#include "common.hpp"
#include "core/config_io.hpp"
#include "core/process.hpp"
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

const std::vector<std::string> kExact{"render.termination_transmittance=0",
                                      "eval.reuse_frames=false", "render.train_recompute=always"};

// The config overrides of a path.
std::vector<std::string> path_overrides(const std::string& path) {
  if (path == "exact") {
    auto o = kExact;
    o.push_back("precision=fp32");
    o.push_back("fp32_products=blas");
    return o;
  }
  if (path == "blas") return {"precision=fp32", "fp32_products=blas"};
  if (path == "fp32" || path == "bf16" || path == "auto") return {"precision=" + path};
  if (path == "default") return {};
  throw std::runtime_error("unknown path '" + path + "' (exact, blas, fp32, bf16, auto, default)");
}

struct Setup {
  fs::path config, checkpoint, scratch;
  std::vector<std::string> overrides;
  std::string path, reference;  // this child's path and the reference path (the first)
  bool is_reference() const { return path == reference; }
  Config load(std::vector<std::string> more = {}) const {
    auto all = overrides;
    const auto p = path_overrides(path);
    all.insert(all.end(), p.begin(), p.end());
    all.insert(all.end(), more.begin(), more.end());
    return config::load<Config>(config, all);
  }
};

// One path of one section runs in a child process of its own (the allocator policy is
// process-wide: the exact path keeps glibc's defaults, as main did). It writes its rows as
// "key<TAB>seconds<TAB>markdown cells" to `rows`; the parent pairs the exact and default rows
// of each key and adds the speed-up.
struct Rows {
  std::ofstream out;
  void add(const std::string& key, double seconds, const std::string& cells) {
    out << key << '\t' << seconds << '\t' << cells << std::endl;
  }
};

void view_section(const Setup& setup, Rows& rows, const std::vector<int>& view_samples) {
  const Config base = setup.load({"data.ratio=1"});
  const auto smpl = data::load_body_model(base.data);
  const data::Dataset dataset(base.data, base.eval.setting, data::Dataset::Mode::Test, smpl);
  model::TransHuman net(base.model);
  pipeline::load_weights(*net, setup.checkpoint, base.eval.model_mismatch == MismatchPolicy::warn);
  net->eval();
  net->set_products(model::resolve_products(base.precision, base.fp32_products, torch::kCPU));
  pipeline::Tokens tokens(*net, smpl->v_template);
  const auto sample = dataset.load(0, 0);
  const auto inputs =
      pipeline::frame_inputs(sample, smpl->v_template, tokens.labels(sample.body), torch::kCPU);
  const auto rays = pipeline::sample_rays(sample, torch::kCPU);
  torch::NoGradGuard no_grad;
  render::Profile prepare_profile;
  net->set_profile(&prepare_profile);
  double prepare_mib = 0;
  auto t0 = Clock::now();
  const auto cache = [&] {
    bench::PeakMemory mem;
    auto c = pipeline::prepare_frame(*net, inputs, base.render);
    prepare_mib = mem.tensor_mib();
    return c;
  }();
  const double prepare = seconds_since(t0);
  net->set_profile(nullptr);
  std::string prepare_stages;
  for (const auto& [stage, seconds] : prepare_profile.seconds)
    prepare_stages += ", " + stage + " " + fmt(seconds, 2);
  rows.add("what", 0,
           sample.human + " frame " + std::to_string(sample.frame) + " view " +
               std::to_string(sample.target_view) + ", " +
               std::to_string(sample.target_image.size(1)) + "x" +
               std::to_string(sample.target_image.size(0)) + ", " + std::to_string(rays.size()) +
               " in-box rays; frame preparation, " + setup.path + " path: " + fmt(prepare, 2) +
               " s" + prepare_stages + ", peak " + fmt(prepare_mib, 0) + " MiB tensors, of which " +
               fmt(cache.nbytes() / 1048576.0, 0) + " MiB stay in the frame cache");
  for (int samples : view_samples) {
    auto rc = base.render;
    rc.samples = samples;
    render::Profile profile;
    net->set_profile(&profile);
    bench::PeakMemory mem;
    t0 = Clock::now();
    const auto img = pipeline::render(*net, cache, rays, rc, pipeline::kInference, &profile);
    const double sec = seconds_since(t0);
    net->set_profile(nullptr);
    const fs::path reference_file =
        setup.scratch / ("view_" + setup.reference + "_" + std::to_string(samples) + ".pt");
    std::string diff = "- | -";
    if (setup.is_reference()) {
      torch::save(std::vector<torch::Tensor>{img.rgb, img.acc}, reference_file.string());
    } else {
      std::vector<torch::Tensor> ref;
      torch::load(ref, reference_file.string());
      const auto drgb = (img.rgb - ref[0]).abs(), dacc = (img.acc - ref[1]).abs();
      diff = fmt(drgb.max().item<double>() * 1e3, 3) + "e-3 (mean " +
             fmt(drgb.mean().item<double>() * 1e3, 3) + "e-3) | " +
             fmt(dacc.max().item<double>() * 1e3, 3) + "e-3 (mean " +
             fmt(dacc.mean().item<double>() * 1e3, 3) + "e-3; " +
             std::to_string(dacc.gt(0.01).sum().item<int64_t>()) + " rays above 0.01)";
    }
    const auto& st = img.stats;
    const std::string stages = bench::stage_seconds(profile);
    rows.add(std::to_string(samples), sec + prepare,
             std::to_string(samples) + " | " + setup.path + " | " + fmt(sec, 2) + " | " +
                 fmt(prepare, 2) + " | " + fmt(sec + prepare, 2) + " | " +
                 std::to_string(st.density_points) + " | " + std::to_string(st.color_points) +
                 " | " + std::to_string(st.terminated_points) + " | " + fmt(mem.tensor_mib(), 0) +
                 " | " + diff + " | " + stages);
  }
}

void orbit_section(const Setup& setup, Rows& rows, int views) {
  const Config c = setup.load({"data.ratio=1"});
  const inference::Session session(c, torch::kCPU, setup.checkpoint);
  inference::VideoRequest request;
  request.orbit_views = views;
  request.force = true;
  request.contact_sheet_frames = 0;
  // Every round renders every view: an earlier round's frames would be resumed, not rendered.
  const fs::path dir = setup.scratch / ("orbit_" + setup.path);
  fs::remove_all(dir);
  const auto t0 = Clock::now();
  const auto summary = inference::render_video(session, request, dir);
  const double sec = seconds_since(t0);
  rows.add("orbit", sec,
           setup.path + " | " + std::to_string(summary.rendered) + " | " + fmt(sec, 1) + " | " +
               fmt(sec / std::max(summary.rendered, 1), 2));
}

// Mean time_per_step of the last metrics line (the steps after the warm-up).
double step_seconds(const fs::path& metrics) {
  std::ifstream in(metrics);
  std::string line, last;
  while (std::getline(in, line))
    if (!line.empty()) last = line;
  const auto row = nlohmann::json::parse(last, nullptr, /*allow_exceptions=*/false);
  if (!row.is_object() || !row.contains("time_per_step") || !row["time_per_step"].is_number())
    throw std::runtime_error("no time_per_step in the last line of " + metrics.string());
  return row["time_per_step"].get<double>();
}

std::vector<torch::Tensor> weights_of(const Config& c, const fs::path& checkpoint) {
  model::TransHuman net(c.model);
  pipeline::load_weights(*net, checkpoint);
  std::vector<torch::Tensor> out;
  for (const auto& p : net->parameters()) out.push_back(p.detach().clone());
  return out;
}

void train_section(const Setup& setup, Rows& rows, int steps) {
  const Config c = setup.load({"train.log_every_steps=" + std::to_string(steps),
                               "train.val_views=0", "train.save_every_epochs=0"});
  const fs::path dir = setup.scratch / ("train_" + setup.path);
  fs::remove_all(dir);
  train::train(c, torch::kCPU, {dir, false, 2 * steps});
  const double sec = step_seconds(dir / "metrics.jsonl");
  std::string same = "-";
  if (!setup.is_reference()) {
    const auto a = weights_of(c, dir / "checkpoints" / "latest.pt");
    const auto b =
        weights_of(c, setup.scratch / ("train_" + setup.reference) / "checkpoints" / "latest.pt");
    size_t differing = 0;
    double largest = 0;
    for (size_t i = 0; i < a.size(); ++i) {
      differing += !torch::equal(a[i], b[i]);
      largest = std::max(largest, (a[i] - b[i]).abs().max().item<double>());
    }
    same = differing == 0 ? "identical to " + setup.reference
                          : std::to_string(differing) + " tensors differ from " + setup.reference +
                                " (largest " + fmt(largest * 1e6, 2) + "e-6)";
  }
  rows.add("train", sec, setup.path + " | " + fmt(sec, 3) + " | " + fmt(1 / sec, 3) + " | " + same);
}

// PSNR of the prediction in evaluation panel b against the one in panel a (8-bit PNGs). The
// prediction is the panel's first tile, below an 18-pixel caption strip (pipeline::panel); the
// synthetic data's images are square, so the tile is as wide as it is high.
double psnr_between(const fs::path& a, const fs::path& b) {
  const cv::Mat x = cv::imread(a.string()), y = cv::imread(b.string());
  if (x.empty() || y.empty() || x.size() != y.size() || x.rows <= 18 || x.cols < x.rows - 18)
    throw std::runtime_error("cannot compare " + a.string() + " and " + b.string());
  const cv::Rect tile(0, 18, x.rows - 18, x.rows - 18);
  cv::Mat d;
  cv::absdiff(x(tile), y(tile), d);
  d.convertTo(d, CV_64F, 1.0 / 255);
  const double mse = cv::mean(d.mul(d))[0];
  return mse == 0 ? std::numeric_limits<double>::infinity() : -10 * std::log10(mse);
}

void eval_section(const Setup& setup, Rows& rows, bool images) {
  const Config c = setup.load({std::string("eval.save_images=") + (images ? "true" : "false")});
  const fs::path dir = setup.scratch / ("eval_" + setup.path);
  fs::remove_all(dir);
  fs::create_directories(dir);
  const auto t0 = Clock::now();
  const auto s = eval::evaluate(c, torch::kCPU, setup.checkpoint, dir);
  const double sec = seconds_since(t0);
  const fs::path psnr_file = setup.scratch / ("eval_" + setup.reference + "_scores.txt");
  int64_t points = 0;
  for (const auto& i : s.per_image) points += i.evaluated_points;
  std::string worst = "- | - | -";
  if (setup.is_reference()) {
    std::ofstream f(psnr_file);
    f << std::setprecision(17) << s.psnr << ' ' << s.ssim << '\n';
    for (const auto& i : s.per_image) f << std::setprecision(17) << i.psnr << '\n';
  } else {
    std::ifstream f(psnr_file);
    double w = 0, v = 0, ref_psnr = 0, ref_ssim = 0;
    f >> ref_psnr >> ref_ssim;
    for (const auto& i : s.per_image) {
      if (!(f >> v))
        throw std::runtime_error("fewer reference images than " + setup.path + " ones in " +
                                 psnr_file.string());
      w = std::max(w, std::abs(i.psnr - v));
    }
    worst = fmt(w, 4) + " dB (mean " + fmt(s.psnr - ref_psnr, 4) + " dB, SSIM " +
            fmt(s.ssim - ref_ssim, 5) + ")";
    // Each rendered panel against the reference path's (8-bit PNGs).
    std::string render_psnr = "-";
    if (images) {
      double lowest = std::numeric_limits<double>::infinity();
      int compared = 0;
      for (const auto& e : fs::directory_iterator(dir / "images")) {
        const auto other =
            setup.scratch / ("eval_" + setup.reference) / "images" / e.path().filename();
        if (!fs::exists(other)) continue;
        lowest = std::min(lowest, psnr_between(other, e.path()));
        ++compared;
      }
      render_psnr =
          compared ? fmt(lowest, 1) + " dB (" + std::to_string(compared) + " panels)" : "no panels";
    }
    worst += " | " + render_psnr + " | " + setup.reference;
  }
  rows.add("eval", sec,
           setup.path + " | " + std::to_string(s.images) + " | " + fmt(sec, 1) + " | " +
               fmt(sec / std::max(s.images, 1), 3) + " | " + fmt(s.psnr, 3) + " | " +
               fmt(s.ssim, 4) + " | " + std::to_string(points) + " | " + worst);
}

struct Row {
  std::string key;
  double seconds;
  std::string cells;
};

std::vector<Row> read_rows(const fs::path& file) {
  std::ifstream in(file);
  std::vector<Row> out;
  std::string line;
  while (std::getline(in, line)) {
    const auto a = line.find('\t'), b = line.find('\t', a + 1);
    if (a == std::string::npos || b == std::string::npos) continue;
    out.push_back(
        {line.substr(0, a), std::stod(line.substr(a + 1, b - a - 1)), line.substr(b + 1)});
  }
  return out;
}

// Header lines and table heads of each section.
void section_head(bench::Report& r, const std::string& section, const Setup& setup, int orbit_views,
                  int steps) {
  if (section == "view") {
    r.line("## One test view at data.ratio 1");
    r.line("");
    r.line(
        "| samples | path | render s | frame preparation s | view s | points evaluated | colour "
        "points | skipped "
        "by termination | peak MiB tensors (render, frame cache held) | per-ray abs rgb diff | "
        "per-ray abs acc diff | seconds per stage | "
        "speed-up (view) |");
    r.line("|---|---|---|---|---|---|---|---|---|---|---|---|---|");
    r.line("");
    r.line(
        "Differences are against the first path. Compositing gives a ray's last sample a 1e10 "
        "segment, so a ray's "
        "acc is a step function of that sample's density near zero: a small change of sign there "
        "moves the ray's "
        "acc by up to 1 and its colour by up to that sample's colour.");
    r.line("");
  } else if (section == "orbit") {
    r.line("## Orbit: " + std::to_string(orbit_views) +
           " views of one frame at data.ratio 1 (transhuman-render)");
    r.line("");
    r.line("| path | views | seconds | seconds per view | speed-up |");
    r.line("|---|---|---|---|---|");
  } else if (section == "train") {
    r.line("## Training at the config: " + std::to_string(steps) + " steps measured after " +
           std::to_string(steps) + " of warm-up, from the same initial weights");
    r.line("");
    r.line("| path | seconds per step | steps per second | weights after the steps | speed-up |");
    r.line("|---|---|---|---|---|");
  } else if (section == "eval") {
    r.line("## Evaluation of the config's setting (transhuman-eval, every image)");
    r.line("");
    r.line(
        "| path | images | seconds | seconds per image | PSNR | SSIM | points evaluated | largest "
        "per-image PSNR "
        "difference (mean PSNR, SSIM difference) | lowest PSNR of a rendered image against the "
        "reference path's | "
        "reference path | speed-up |");
    r.line("|---|---|---|---|---|---|---|---|---|---|---|");
  }
}

}  // namespace

int run(int argc, char** argv) {
  CLI::App cli{
      "TransHuman speed benchmark: several paths side by side (exact, blas, fp32, bf16, default)"};
  Setup setup;
  int threads = 0, orbit_views = 36, train_steps = 10;
  fs::path out = "bench/results/speed.md", rows_file;
  std::vector<std::string> sections{"view", "orbit", "train", "eval"};
  std::vector<int> view_samples{64, 16};
  std::string child_path;
  std::vector<std::string> paths{"exact", "default"};
  int repeat = 1;
  bool eval_images = false;
  cli.add_option("--config", setup.config, "the config (the checkpoint's)")->required();
  cli.add_option("--checkpoint", setup.checkpoint, "a trained checkpoint")->required();
  cli.add_option("--out", out, "append the figures to this markdown file (empty: print only)");
  cli.add_option("--sections", sections, "which parts to run: view orbit train eval")
      ->check(CLI::IsMember({"view", "orbit", "train", "eval"}));
  cli.add_option("--view-samples", view_samples, "samples per ray of the view section");
  cli.add_option("--orbit-views", orbit_views, "orbit views");
  cli.add_option("--train-steps", train_steps,
                 "training steps measured (after as many of warm-up)");
  cli.add_option("--threads", threads, "LibTorch threads (0: one per core)");
  cli.add_option("--scratch", setup.scratch,
                 "scratch folder (default: a temporary one, removed at the end)");
  cli.add_option(
         "--paths", paths,
         "paths side by side; the first is the reference: exact blas fp32 bf16 auto default")
      ->check(CLI::IsMember({"exact", "blas", "fp32", "bf16", "auto", "default"}));
  cli.add_option("--repeat", repeat, "rounds of all paths, alternating")->check(CLI::Range(1, 10));
  cli.add_flag("--eval-images", eval_images,
               "evaluation saves its images, compared with the reference path's");
  cli.add_option("--child", child_path, "(internal) run one path of the sections");
  cli.add_option("--reference", setup.reference, "(internal) the reference path");
  cli.add_option("--rows", rows_file, "(internal) where a child writes its rows");
  cli.add_option("overrides", setup.overrides, "config overrides key=value");
  if (const auto rc = app::parse_command_line(cli, argc, argv)) return *rc;
  if (!child_path.empty()) {  // one path, in a process of its own
    setup.path = child_path;
    if (child_path != "exact")
      runtime::keep_freed_memory();  // as the apps do; exact: glibc defaults
    runtime::set_threads(threads);
    Rows rows{std::ofstream(rows_file)};
    try {
      for (const auto& s : sections) {
        if (s == "view")
          view_section(setup, rows, view_samples);
        else if (s == "orbit")
          orbit_section(setup, rows, orbit_views);
        else if (s == "train")
          train_section(setup, rows, train_steps);
        else if (s == "eval")
          eval_section(setup, rows, eval_images);
        else
          throw std::runtime_error("unknown section '" + s + "' (view, orbit, train, eval)");
      }
    } catch (const std::exception& e) {
      std::cerr << "transhuman-bench-speed (" << child_path << "): error: " << e.what()
                << std::endl;
      return 1;
    }
    return 0;
  }

  const bool own_scratch = setup.scratch.empty();
  if (own_scratch)
    setup.scratch =
        fs::temp_directory_path() / ("transhuman-bench-speed-" + std::to_string(::getpid()));
  fs::create_directories(setup.scratch);
  bench::Report r;
  const std::time_t now = std::time(nullptr);
  char date[32];
  std::strftime(date, sizeof date, "%Y-%m-%d %H:%M UTC", std::gmtime(&now));
  std::string names;
  for (const auto& p : paths) names += (names.empty() ? "" : ", ") + p;
  r.line("# Speed: paths " + names + " (" + std::string(date) + ")");
  r.line("");
  const auto commit = bench::git_commit();
  r.line("Config " + setup.config.string() + ", checkpoint " + setup.checkpoint.string() +
         "; commit " + commit + "; LibTorch " + std::string(TORCH_VERSION) + ", BLAS " +
         runtime::detect_blas().name + ", threads " +
         (threads > 0 ? std::to_string(threads) : "one per core") + "; processor " +
         bench::cpu_model() + " (bf16: " + runtime::detect_cpu_bf16().describe() + "), " +
         std::to_string(std::thread::hardware_concurrency()) + " cores, load average at start " +
         bench::load_average() + ".");
  std::string exact;
  for (const auto& o : path_overrides("exact")) exact += (exact.empty() ? "" : ", ") + o;
  r.line("Paths: exact = " + exact +
         ", glibc malloc defaults (the changes without a switch - vectorised attention "
         "and DPaRF loops, colour without a row copy, OpenMP in the project's kernels - are in "
         "every path); blas = "
         "precision=fp32, fp32_products=blas; fp32 / bf16 / auto = that precision; default = the "
         "config as it is. "
         "Every path but exact keeps freed memory (as the apps do). Each run of a path is a "
         "process of its own; "
         "with --repeat the paths alternate (" +
         std::to_string(repeat) + " round" + (repeat > 1 ? "s" : "") +
         "). Speed-ups and differences are against " + paths.front() + " of the same round.");
  r.line("");
  for (const auto& section : sections) {
    std::vector<std::pair<std::string, std::vector<Row>>> runs;  // (path, rows) in run order
    for (int round = 0; round < repeat; ++round)
      for (const auto& path : paths) {
        const fs::path file =
            setup.scratch / (section + "_" + path + "_" + std::to_string(round) + ".rows");
        std::vector<std::string> args{fs::read_symlink("/proc/self/exe").string(),
                                      "--child",
                                      path,
                                      "--reference",
                                      paths.front(),
                                      "--rows",
                                      file.string(),
                                      "--config",
                                      setup.config.string(),
                                      "--checkpoint",
                                      setup.checkpoint.string(),
                                      "--scratch",
                                      setup.scratch.string(),
                                      "--sections",
                                      section,
                                      "--orbit-views",
                                      std::to_string(orbit_views),
                                      "--train-steps",
                                      std::to_string(train_steps),
                                      "--threads",
                                      std::to_string(threads),
                                      "--view-samples"};
        for (int v : view_samples) args.push_back(std::to_string(v));
        if (eval_images) args.push_back("--eval-images");
        args.push_back("--");
        args.insert(args.end(), setup.overrides.begin(), setup.overrides.end());
        std::cout << "[" << section << ", " << path << ", round " << round + 1 << "]" << std::endl;
        if (run_program(args) != 0) {
          std::cerr << "transhuman-bench-speed: the " << path << " run of section " << section
                    << " failed" << std::endl;
          if (own_scratch) fs::remove_all(setup.scratch);
          return 1;
        }
        runs.emplace_back(path, read_rows(file));
      }
    section_head(r, section, setup, orbit_views, train_steps);
    std::string what;
    std::map<std::string, double> reference_seconds;
    for (size_t i = 0; i < runs.size(); ++i) {
      const auto& [path, rows] = runs[i];
      if (i % paths.size() == 0) {  // a new round: its reference path's figures
        reference_seconds.clear();
        for (const auto& row : rows) reference_seconds[row.key] = row.seconds;
      }
      for (const auto& row : rows) {
        if (row.key == "what") {
          if (i < paths.size()) what += (what.empty() ? "" : "; ") + row.cells;
          continue;
        }
        r.line("| " + row.cells + " | " +
               fmt(reference_seconds[row.key] / std::max(row.seconds, 1e-9), 2) + "x |");
      }
    }
    if (!what.empty()) r.line("\nThe view: " + what + ".");
    r.line("");
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

int main(int argc, char** argv) {
  return app::guarded_main("transhuman-bench-speed", [&] { return run(argc, argv); });
}
