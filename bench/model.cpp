// Model and renderer benchmark (METHOD 3, 4, 9): per-point throughput of DPaRF + FDI + heads at
// several chunk sizes, one training step on the default ray batch, and one 512 x 512 frame
// rendered progressively, for 64 and 16 samples per ray. Synthetic inputs (random images, a
// humanoid point body of 6890 vertices, 300 tokens); random weights.
//   transhuman-bench-model [--threads N] [--out FILE [--force]] [--quick] [--precision fp32-blas
//   fp32 bf16 ...]
// Each precision path (model/precision.hpp: fp32-blas = fp32 products through BLAS, fp32 = the
// config default's fp32 products, bf16, auto) is measured in turn inside every round, so that
// the paths see the same machine state.
// Memory: peak resident set size of the process during the measured section, minus the
// resident size before it (Linux VmHWM after resetting it through /proc/self/clear_refs).
#include <ATen/Parallel.h>
#include <malloc.h>
#include <torch/csrc/autograd/profiler_legacy.h>
#include <torch/torch.h>

#include <CLI/CLI.hpp>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <iomanip>
#include <iostream>
#include <map>
#include <sstream>
#include <thread>

#include "app/app.hpp"
#include "common.hpp"
#include "core/error.hpp"
#include "core/files.hpp"
#include "core/runtime.hpp"
#include "core/torch_compat.hpp"
#include "model/kernels/onednn_linear.hpp"
#include "model/transhuman.hpp"
#include "pipeline/pipeline.hpp"
#include "render/progressive.hpp"

using namespace th;
using bench::Clock;
using bench::fmt;
using bench::PeakMemory;
using bench::seconds_since;
using bench::stage_rows;
namespace fs = std::filesystem;

namespace {

torch::Tensor rotation_y(double a) {
  return torch::tensor(
             {std::cos(a), 0.0, std::sin(a), 0.0, 1.0, 0.0, -std::sin(a), 0.0, std::cos(a)})
      .view({3, 3});
}

// A humanoid of ellipsoid surfaces (metres, SMPL-like frame), nv points.
torch::Tensor humanoid(int64_t nv) {
  struct Part {
    double c[3], r[3], share;
  };
  const Part parts[] = {
      {{0, 0.25, 0}, {0.17, 0.28, 0.11}, 0.3},      {{0, 0.68, 0}, {0.09, 0.12, 0.1}, 0.1},
      {{-0.1, -0.45, 0}, {0.08, 0.42, 0.08}, 0.15}, {{0.1, -0.45, 0}, {0.08, 0.42, 0.08}, 0.15},
      {{-0.33, 0.3, 0}, {0.22, 0.05, 0.05}, 0.15},  {{0.33, 0.3, 0}, {0.22, 0.05, 0.05}, 0.15}};
  std::vector<torch::Tensor> out;
  int64_t left = nv;
  for (size_t i = 0; i < std::size(parts); ++i) {
    const auto& p = parts[i];
    const int64_t n = i + 1 == std::size(parts) ? left : static_cast<int64_t>(p.share * nv);
    left -= n;
    auto d = torch::randn({n, 3}, torch::kDouble);
    d = d / d.norm(2, 1, true);
    out.push_back(d * torch::tensor({p.r[0], p.r[1], p.r[2]}, torch::kDouble) +
                  torch::tensor({p.c[0], p.c[1], p.c[2]}, torch::kDouble));
  }
  return torch::cat(out);
}

struct Scene {
  model::FrameInputs in;
  torch::Tensor K, R, T;  // target camera
  int64_t size;
};

Scene make_scene(int64_t size, int64_t nv, int64_t nt) {
  torch::manual_seed(0);
  Scene s;
  s.size = size;
  auto& in = s.in;
  in.canonical = humanoid(nv);
  in.A = (torch::eye(3).expand({nv, 3, 3}) + 0.05 * torch::randn({nv, 3, 3})).contiguous();
  in.Rh = rotation_y(0.4).to(torch::kFloat);
  in.Th = torch::tensor({0.2f, 0.9f, -0.3f});
  const auto xs = in.canonical.to(torch::kFloat) + 0.01 * torch::randn({nv, 3});
  in.vertices = torch::mm(xs, in.Rh.t()) + in.Th;
  // Voronoi clusters around farthest-point seeds: nt non-empty tokens.
  std::vector<int64_t> seeds{0};
  auto dmin = (in.canonical - in.canonical[0]).norm(2, 1);
  for (int64_t i = 1; i < nt; ++i) {
    const int64_t j = dmin.argmax().item<int64_t>();
    seeds.push_back(j);
    dmin = torch::minimum(dmin, (in.canonical - in.canonical[j]).norm(2, 1));
  }
  const auto seed_pts = in.canonical.index_select(0, torch::tensor(seeds));
  in.labels = std::get<1>(torch::cdist(in.canonical, seed_pts).min(1));
  in.num_tokens = nt;
  const double f = size * 1.15;
  const auto K = torch::tensor({f, 0.0, size / 2.0, 0.0, f, size / 2.0, 0.0, 0.0, 1.0})
                     .view({3, 3})
                     .to(torch::kFloat);
  std::vector<torch::Tensor> Ks, Rs, Ts;
  for (int v = 0; v < 4; ++v) {
    const auto R = rotation_y(2 * M_PI * v / 4 + 0.3).to(torch::kFloat);
    Ks.push_back(K);
    Rs.push_back(R);
    Ts.push_back((torch::tensor({0.0f, 0.0f, 3.5f}) - torch::mv(R, in.Th)).view({3, 1}));
  }
  in.K = torch::stack({Ks[0], Ks[1], Ks[2]});
  in.R = torch::stack({Rs[0], Rs[1], Rs[2]});
  in.T = torch::stack({Ts[0], Ts[1], Ts[2]});
  s.K = Ks[3], s.R = Rs[3], s.T = Ts[3];
  in.ref_images = torch::rand({3, 3, size, size});
  in.visibility = torch::rand({3, nv}) < 0.6;
  return s;
}

// All rays of the target view that meet the body's box (padded 0.05 m on z like METHOD 2.2).
render::Rays box_rays(const Scene& s, torch::Tensor* pixel_index = nullptr) {
  const auto n = s.size;
  const auto grid =
      torch::meshgrid({torch::arange(n, torch::kFloat), torch::arange(n, torch::kFloat)}, "ij");
  const auto pix = torch::stack({grid[1].flatten(), grid[0].flatten(), torch::ones({n * n})}, 1);
  const auto d = torch::mm(torch::mm(pix, torch::inverse(s.K).t()), s.R);
  const auto o = -torch::mv(s.R.t(), s.T.flatten());
  const auto lo = std::get<0>(s.in.vertices.min(0)) - torch::tensor({0.0f, 0.0f, 0.05f});
  const auto hi = std::get<0>(s.in.vertices.max(0)) + torch::tensor({0.0f, 0.0f, 0.05f});
  const auto dd = torch::where(d.abs() < 1e-5, torch::full_like(d, 1e-5), d);
  const auto t0 = (lo - o) / dd, t1 = (hi - o) / dd;
  const auto tmin = std::get<0>(torch::minimum(t0, t1).max(1)),
             tmax = std::get<0>(torch::maximum(t0, t1).min(1));
  const auto idx = ((tmax > tmin) & (tmin > 0)).nonzero().flatten();
  if (pixel_index) *pixel_index = idx;
  return {o.unsqueeze(0).expand({idx.size(0), 3}).contiguous(), d.index_select(0, idx),
          tmin.index_select(0, idx), tmax.index_select(0, idx)};
}

// METHOD 5: 6 patches of 20 x 20 around random in-box pixels (clipped, overlapping allowed).
render::Rays patch_rays(const Scene& s) {
  torch::Tensor pix;
  const auto all = box_rays(s, &pix);
  auto is_valid = torch::full({s.size * s.size}, -1, torch::kLong);
  is_valid.index_put_({pix}, torch::arange(pix.size(0)));
  std::vector<torch::Tensor> rows;
  for (int p = 0; p < 6; ++p) {
    const int64_t c = pix[torch::randint(pix.size(0), {1}).item<int64_t>()].item<int64_t>();
    const int64_t cy = c / s.size, cx = c % s.size;
    for (int64_t y = std::max<int64_t>(cy - 10, 0); y < std::min(cy + 10, s.size); ++y) {
      const auto seg = is_valid.slice(0, y * s.size + std::max<int64_t>(cx - 10, 0),
                                      y * s.size + std::min(cx + 10, s.size));
      rows.push_back(seg.index_select(0, (seg >= 0).nonzero().flatten()));
    }
  }
  return all.index(torch::cat(rows));
}

// Points the renderer evaluates: samples of in-box rays within the culling distance.
torch::Tensor body_points(const Scene& s, const render::BodyDistance& body, int64_t count,
                          torch::Tensor* dirs) {
  auto rays = box_rays(s);
  const auto z = render::sample_depths(rays.near, rays.far, 64, false);
  auto pts =
      (rays.origins.unsqueeze(1) + rays.directions.unsqueeze(1) * z.unsqueeze(2)).reshape({-1, 3});
  auto d = rays.directions.unsqueeze(1).expand({rays.size(), 64, 3}).reshape({-1, 3});
  const auto keep = body.near(pts).nonzero().flatten();
  const auto pick = keep.index_select(
      0, torch::randperm(keep.size(0)).narrow(0, 0, std::min(count, keep.size(0))));
  // Keep ray order (renderer chunks hold consecutive samples of neighbouring rays).
  const auto sorted = std::get<0>(pick.sort());
  *dirs = d.index_select(0, sorted);
  return pts.index_select(0, sorted);
}

using bench::Report;

// Memory bandwidth in GB/s: a stream triad a = b + s c over three 64 MiB float arrays on the
// LibTorch threads, best of the repetitions in about half a second (12 bytes per element:
// two reads and a write, the write-allocate read not counted, as STREAM counts).
double stream_bandwidth() {
  const int64_t n = int64_t(1) << 24;
  std::vector<float> a(n), b(n, 1.0f), c(n, 2.0f);
  double best = 0;
  const auto t0 = Clock::now();
  while (seconds_since(t0) < 0.5) {
    const auto t = Clock::now();
    at::parallel_for(0, n, 1 << 16, [&](int64_t lo, int64_t hi) {
      float* __restrict pa = a.data();
      const float* __restrict pb = b.data();
      const float* __restrict pc = c.data();
      for (int64_t i = lo; i < hi; ++i) pa[i] = pb[i] + 3.0f * pc[i];
    });
    best = std::max(best, 12.0 * double(n) / seconds_since(t) / 1e9);
  }
  return best;
}

// GFLOP/s of the product the model's linear layers run under `products`: a (rows, 256) by
// (256, 256) product, the shape of the per-point layers at a chunk, for about half a second.
double product_limit(const model::Products& products, int64_t rows) {
  torch::NoGradGuard ng;
  const auto x = torch::randn({rows, 256}), w = torch::randn({256, 256}) * 0.05,
             b = torch::zeros({256});
  const auto in = products.bf16() ? x.to(torch::kBFloat16) : x;
  products.linear(in, w, b);  // warm-up (weight reorders)
  int64_t calls = 0;
  const auto t0 = std::chrono::steady_clock::now();
  double elapsed = 0;
  while (elapsed < 0.5) {
    products.linear(in, w, b);
    ++calls;
    elapsed = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  }
  return 2.0 * double(rows) * 256 * 256 * double(calls) / elapsed / 1e9;
}

void shares_into(std::string& s, const render::Profile& p, double total) {
  std::vector<std::pair<std::string, double>> v;
  for (const auto& row : stage_rows(p, false)) v.emplace_back(row.stage, row.seconds);
  std::sort(v.begin(), v.end(), [](auto& a, auto& b) { return a.second > b.second; });
  double listed = 0;
  for (const auto& [k, sec] : v) {
    s += " " + k + " " + fmt(100 * sec / total) + "% (" + fmt(sec, 2) + " s),";
    listed += sec;
  }
  s += " other " + fmt(100 * std::max(0.0, total - listed) / total) + "%";
}

void shares(Report& r, const render::Profile& p, double total) {
  std::string s = "  time per stage:";
  shares_into(s, p, total);
  r.line(s);
}

}  // namespace

int run(int argc, char** argv) {
  CLI::App cli{"TransHuman model and renderer benchmark"};
  int threads = 0;
  std::string out = "bench/results/model.md";
  bool quick = false, force = false;
  std::vector<int64_t> chunks{1024, 2048, 4096, 8192, 16384, 32768, 65536};
  cli.add_option("--threads", threads, "LibTorch threads (0: one per core)");
  cli.add_option("--out", out, "write the figures to this file (markdown; empty: print only)")
      ->capture_default_str();
  cli.add_flag("--force", force, "replace --out when it exists");
  cli.add_option("--chunks", chunks, "chunk sizes for the per-point figures");
  int rounds = 3;
  cli.add_option("--rounds", rounds, "rounds of per-point measurements (best of)");
  cli.add_flag("--quick", quick, "small image and fewer repetitions (smoke run)");
  int64_t train_chunk = RenderConfig{}.train_chunk_points,
          render_chunk = RenderConfig{}.chunk_points;
  cli.add_option("--train-chunk", train_chunk, "render.train_chunk_points for the training step");
  cli.add_option("--render-chunk", render_chunk, "render.chunk_points for the image");
  std::vector<std::string> sections{"points", "train", "render"};
  cli.add_option("--sections", sections, "which parts to run: points train render");
  std::vector<std::string> precisions{"fp32"};
  cli.add_option("--precision", precisions,
                 "precision paths side by side: fp32-blas fp32 bf16 auto")
      ->check(CLI::IsMember({"fp32-blas", "fp32", "bf16", "auto"}));
  std::string trace;
  cli.add_option("--trace", trace,
                 "write a Chrome trace of three forward+backward calls and one training-path call "
                 "to this file");
  bool system_malloc = false;
  cli.add_flag("--system-malloc", system_malloc, "keep glibc's default mmap use for large blocks");
  if (const auto rc = app::parse_command_line(cli, argc, argv)) return *rc;
  bench::refuse_overwriting(out, force);
  // The trace goes to a new file or over a regular one, never through a link or into a device.
  bool trace_existed = false;
  if (!trace.empty()) {
    std::error_code ec;
    auto type = fs::symlink_status(trace, ec).type();
    if (ec) type = fs::file_type::not_found;  // an unreadable folder: the write below reports it
    trace_existed = type != fs::file_type::not_found;
    if (type == fs::file_type::symlink)
      fail("--trace '", trace,
           "' is a symbolic link: the trace is written to a new or a regular file only");
    if (trace_existed && type != fs::file_type::regular)
      fail("--trace '", trace, "' is a ", file_kind(type),
           ": the trace is written to a new or a regular file only");
  }
  // Per-chunk tensors are tens of MB: glibc would map and unmap them every time (page faults
  // dominate the system time). Serve them from the heap and keep it.
  if (!system_malloc) {
    mallopt(M_MMAP_MAX, 0);
    mallopt(M_TRIM_THRESHOLD, std::numeric_limits<int>::max());
  }
  const int nthreads = runtime::set_threads(threads);
  const int64_t size = quick ? 128 : 512;

  // A precision path: fp32, bf16, auto, or fp32-blas (fp32 with its products through BLAS).
  auto products_of = [](const std::string& path, std::string* why = nullptr) {
    if (path == "fp32-blas")
      return model::resolve_products(PrecisionChoice::fp32, Fp32Products::blas, torch::kCPU, why);
    return model::resolve_products(config::parse_choice<PrecisionChoice>("--precision", path),
                                   Fp32Products::automatic, torch::kCPU, why);
  };
  Report r;
  r.line("# TransHuman model benchmark");
  r.line("");
  r.line("LibTorch " + std::string(TORCH_VERSION) + ", " + std::to_string(nthreads) +
         " threads, BLAS " + runtime::detect_blas().name + "; synthetic frame: 3 reference views " +
         std::to_string(size) + "x" + std::to_string(size) +
         ", 6890 body vertices, 300 tokens, default model (ViT depth 12), random weights.");
  const char* wait = std::getenv("OMP_WAIT_POLICY");
  r.line(std::string("OMP_WAIT_POLICY=") +
         (wait ? wait : "(unset: libgomp default, active spinning)") + ".");
  const auto loadavg = bench::load_average;
  r.line("Machine: " + std::to_string(std::thread::hardware_concurrency()) +
         " cores shared with other jobs; load average at start " + loadavg() + ".");
  {
    std::string why;
    std::string paths;
    for (const auto& p : precisions) {
      products_of(p, &why);
      paths += (paths.empty() ? "" : "; ") + p + ": " + why;
    }
    r.line("Processor: " + bench::cpu_model() + ", bf16: " + runtime::detect_cpu_bf16().describe() +
           ". Precision paths: " + paths + ".");
  }
  r.line(std::string("Allocator: glibc malloc") +
         (system_malloc ? " (defaults)" : " with M_MMAP_MAX=0, no trimming") + ".");
  r.line(
      "Memory: peak bytes of live LibTorch CPU tensors allocated in the measured section (c10 "
      "memory-reporting "
      "hook on the allocator); in brackets the resident-set growth (VmHWM after a reset via "
      "/proc/self/clear_refs "
      "minus VmRSS before, a lower bound since freed heap memory is reused).");
  r.line("");

  const auto scene = make_scene(size, 6890, 300);
  ModelConfig mc;
  RenderConfig rc;
  rc.train_chunk_points = train_chunk;
  rc.chunk_points = render_chunk;
  torch::manual_seed(1);
  model::TransHuman net(mc);
  {
    const auto counts = model::parameter_counts(*net);
    std::string s = "Parameters: ";
    for (const auto& c : counts) s += c.module + " " + std::to_string(c.count) + ", ";
    r.line(s.substr(0, s.size() - 2));
    r.line("");
  }
  // Densities around zero near the body, so that about half the points are coloured.
  {
    torch::NoGradGuard ng;
    net->eval();
    const auto cache = net->prepare(scene.in, rc.cull_distance);
    torch::Tensor d;
    const auto pts = body_points(scene, *cache.geometry.body, 20000, &d);
    const auto raw = net->forward(cache, pts, d);
    net->heads->alpha_fc->bias.sub_(raw.select(1, 3).median());
  }

  auto wanted = [&](const char* s) {
    return std::find(sections.begin(), sections.end(), s) != sections.end();
  };
  // ---- per-point throughput -----------------------------------------------------------------
  if (wanted("points")) {
    r.line("## Per-point network (DPaRF + FDI + heads, 3 views), points within 0.1 m of the body");
    r.line("");
    r.line(
        "| chunk | precision | forward pts/s | density-first pts/s | fwd+bwd pts/s (one chunk, "
        "graph kept) | training pts/s (no-grad fwd + recompute + bwd, 65536 points per call) | "
        "peak MiB training | forward, fwd+bwd vs " +
        precisions.front() + " |");
    r.line("|---|---|---|---|---|---|---|---|");
    {
      net->train();
      torch::Tensor dirs;
      model::FrameCache cache_ng;
      {
        torch::NoGradGuard ng;
        cache_ng = net->prepare(scene.in, rc.cull_distance);
      }
      const int64_t total = quick ? 16384 : 65536;
      const auto pts = body_points(scene, *cache_ng.geometry.body, total, &dirs);
      const double min_time = quick ? 0.3 : 2.0;
      std::vector<std::string> stage_lines;
      // Frame tensors as leaves: the per-point part only (the frame's own backward is excluded),
      // with gradient sinks for the gathered tables as the training path uses them.
      // (Not the geometry, the token frames or the raw images: no gradient reaches them.)
      // Prepared with autograd on, as training prepares (level tables, not inference's readout
      // windows).
      model::FrameCache cache_g = [&] {
        torch::AutoGradMode grad(true);
        return net->prepare(scene.in, rc.cull_distance);
      }();
      cache_g.visit([](torch::Tensor& t, torch::Tensor* sink) {
        if (!t.defined() || !t.is_floating_point()) return;
        t = t.detach().requires_grad_(true);
        if (sink) *sink = torch::zeros_like(t);
      });
      cache_g.geometry = cache_ng.geometry;
      {
        auto& human = std::get<model::TokenTableStage>(cache_g.human);
        human.frames = {human.frames.origins.detach(), human.frames.rotations.detach()};
        auto& px = std::get<model::PixelReadouts>(cache_g.pixels);
        px.alpha.image_table = px.alpha.image_table.detach();
        px.color.image_table = px.color.image_table.detach();
      }
      // The training path's frame: the frame tensors as fresh leaves without gradient sinks, read
      // by one field call that chunks, recomputes and checkpoints inside.
      auto training_cache = [&] {
        model::FrameCache cache_t = cache_g;
        cache_t.visit([](torch::Tensor& t, torch::Tensor* sink) {
          if (sink) *sink = torch::Tensor();
          if (t.defined() && t.requires_grad()) t = t.detach().requires_grad_(true);
        });
        return cache_t;
      };
      // Operator trace at the first chunk size and precision, for comparing two builds operator by
      // operator (scripts/compare-traces.py): three forward+backward calls (graph kept) and one
      // training-path call of four chunks; then both timed untraced.
      if (!trace.empty()) {
        if (!std::ofstream(trace)) {
          std::cerr << "transhuman-bench-model: cannot write the trace file '" << trace << "'"
                    << std::endl;
          return 1;
        }
        net->set_products(products_of(precisions.front()));
        const int64_t c = std::min<int64_t>(chunks.front(), pts.size(0));
        const int64_t m = std::min<int64_t>(4 * c, pts.size(0));
        auto fwd_bwd = [&] {
          const auto raw = net->forward(cache_g, pts.narrow(0, 0, c), dirs.narrow(0, 0, c));
          raw.backward(torch::ones_like(raw));
        };
        model::FrameCache cache_t = training_cache();
        model::FrameField field(*net, cache_t, c, true);
        auto training = [&] {
          const auto raw = field.raw(pts.narrow(0, 0, m), dirs.narrow(0, 0, m));
          raw.backward(torch::ones_like(raw));
        };
        fwd_bwd(), training();  // warm-up
        {
          torch::autograd::profiler::RecordProfile record(trace);
          for (int i = 0; i < 3; ++i) fwd_bwd();
          training();
        }
        // The profiler writes while it stops and reports nothing: a complete trace ends its event
        // list.
        std::ifstream written(trace);
        const std::string text((std::istreambuf_iterator<char>(written)),
                               std::istreambuf_iterator<char>());
        const auto last = text.find_last_not_of(" \n");
        if (last == std::string::npos || text[last] != ']') {
          // Only a file this run made is removed.
          if (!trace_existed) std::remove(trace.c_str());
          std::cerr << "transhuman-bench-model: the trace file '" << trace
                    << "' was not written completely (disk full?); "
                    << (trace_existed ? "it is left as it is" : "the partial file is removed")
                    << std::endl;
          return 1;
        }
        auto ms_per_call = [](int calls, auto&& fn) {
          const auto t0 = Clock::now();
          for (int i = 0; i < calls; ++i) fn();
          return seconds_since(t0) * 1000 / calls;
        };
        const double fb_ms = ms_per_call(20, fwd_bwd), train_ms = ms_per_call(5, training);
        net->zero_grad();
        std::cout << "Operator trace (" << precisions.front() << "): " << trace
                  << "; untraced: forward+backward of " << c << " points " << fmt(fb_ms, 1)
                  << " ms per call (20 calls), training path of " << m << " points "
                  << fmt(train_ms, 1) << " ms per call (5 calls)" << std::endl;
      }
      // Rounds over all chunk sizes; each cell keeps its best round (the machine is shared).
      struct Cell {
        double fwd = 0, dfirst = 0, fb = 0, train = 0, mem = 0;
        render::Profile profile;
        double fwd_s = 0;
      };
      std::map<std::pair<int64_t, size_t>, Cell> best;
      // The inference frame of each path, prepared under its products (the readout windows are
      // stored in the type the path's products read).
      std::vector<model::FrameCache> inference(precisions.size());
      for (size_t path = 0; path < precisions.size(); ++path) {
        torch::NoGradGuard ng;
        net->set_products(products_of(precisions[path]));
        inference[path] = net->prepare(scene.in, rc.cull_distance);
      }
      for (int round = 0; round < rounds; ++round)
        for (const int64_t chunk : chunks)
          for (size_t path = 0; path < precisions.size(); ++path) {
            if (chunk > pts.size(0)) continue;
            net->set_products(products_of(precisions[path]));
            const auto key = std::make_pair(chunk, path);
            auto rate = [&](auto&& fn) {
              int64_t done = 0;
              fn(pts.narrow(0, 0, chunk), dirs.narrow(0, 0, chunk));  // warm-up
              const auto t0 = Clock::now();
              while (seconds_since(t0) < min_time)
                for (int64_t b = 0;
                     b + chunk <= pts.size(0) && (done == 0 || seconds_since(t0) < min_time);
                     b += chunk) {
                  fn(pts.narrow(0, b, chunk), dirs.narrow(0, b, chunk));
                  done += chunk;
                }
              return done / seconds_since(t0);
            };
            double fwd, dfirst, fb, train;
            render::Profile fwd_profile;
            {
              torch::NoGradGuard ng;
              net->set_profile(&fwd_profile);
              const auto t_fwd = Clock::now();
              fwd = rate([&](const torch::Tensor& p, const torch::Tensor& d) {
                net->forward(inference[path], p, d);
              });
              const double fwd_seconds = seconds_since(t_fwd);
              net->set_profile(nullptr);
              if (fwd > best[key].fwd)
                best[key].profile = fwd_profile, best[key].fwd_s = fwd_seconds;
              dfirst = rate([&](const torch::Tensor& p, const torch::Tensor& d) {
                net->forward_density_first(inference[path], p, d);
              });
            }
            fb = rate([&](const torch::Tensor& p, const torch::Tensor& d) {
              const auto raw = net->forward(cache_g, p, d);
              raw.backward(torch::ones_like(raw));
            });
            // The training path: one field call for all points, chunked and recomputed inside.
            model::FrameCache cache_t = training_cache();
            model::FrameField field(*net, cache_t, chunk, true);
            PeakMemory mem;
            int reps = 0;
            const auto t0 = Clock::now();
            do {
              const auto raw = field.raw(pts, dirs);
              raw.backward(torch::ones_like(raw));
              ++reps;
            } while (seconds_since(t0) < min_time);
            train = reps * pts.size(0) / seconds_since(t0);
            const double train_mem = mem.tensor_mib();
            net->zero_grad();
            auto& c = best[key];
            c.fwd = std::max(c.fwd, fwd), c.dfirst = std::max(c.dfirst, dfirst),
            c.fb = std::max(c.fb, fb);
            c.train = std::max(c.train, train), c.mem = std::max(c.mem, train_mem);
            std::cout << "  round " << round << " chunk " << chunk << " " << precisions[path]
                      << ": " << fmt(fwd, 0) << " " << fmt(dfirst, 0) << " " << fmt(fb, 0) << " "
                      << fmt(train, 0) << std::endl;
          }
      for (auto& [key, c] : best) {
        const auto& base = best[{key.first, 0}];
        r.line("| " + std::to_string(key.first) + " | " + precisions[key.second] + " | " +
               fmt(c.fwd, 0) + " | " + fmt(c.dfirst, 0) + " | " + fmt(c.fb, 0) + " | " +
               fmt(c.train, 0) + " | " + fmt(c.mem, 0) + " | " + fmt(c.fwd / base.fwd, 2) + "x, " +
               fmt(c.fb / base.fb, 2) + "x |");
        stage_lines.push_back("chunk " + std::to_string(key.first) + ", " + precisions[key.second] +
                              ":");
        shares_into(stage_lines.back(), c.profile, c.fwd_s);
      }
      r.line("");
      r.line("Best of " + std::to_string(rounds) +
             " rounds over all chunk sizes (points/s). For comparison, the reference "
             "implementation on this machine (METHOD 9): 6,200 forward at its inference chunk of "
             "32,768 points, 2,070 "
             "forward+backward at its training batch of 153,600; 19,900 and 5,100 at its best "
             "chunk (~9,600).");
      r.line(
          "Forward: full colour for every point. Density-first: colour only where sigma > 0 (about "
          "half here).");
      r.line("Forward time per stage:");
      for (const auto& l : stage_lines) r.line("- " + l);
      r.line("");
      // Roofline per stage at each precision's fastest chunk: the work the running form counts
      // (render::count_work), against the product limit and the memory bandwidth measured now.
      const double bandwidth = stream_bandwidth();
      r.line(
          "Roofline of the forward stages (each precision at its fastest chunk). FLOP and bytes "
          "per point are what the running form's operations count as they run: products at "
          "their real (folded) shapes, 2 M K N; the kernels' and the remaining elementwise "
          "operations' arithmetic, a transcendental function as one; bytes: compulsory traffic, "
          "each operand read once and each result written once, a gathered table at most once. "
          "Limits measured in this run: the product limit, a (rows, 256) x (256, 256) product at "
          "the chunk's rows in the path's precision; memory bandwidth, a stream triad " +
          fmt(bandwidth, 1) +
          " GB/s. Bound: memory where the stage's intensity times the bandwidth is below the "
          "product limit; share: the achieved rate over the bound's rate. ns/point: the stage's "
          "wall time per point on the run's threads. A stage's parts follow it (dparf.fields: "
          "the nearest fields inside DPaRF); the stage's row holds them all.");
      r.line("");
      r.line(
          "| precision | chunk | stage | kFLOP/point | bytes/point | FLOP/byte | ns/point | "
          "GFLOP/s | GB/s | product limit GFLOP/s | bound | share of bound |");
      r.line("|---|---|---|---|---|---|---|---|---|---|---|---|");
      for (size_t path = 0; path < precisions.size(); ++path) {
        const Cell* fastest = nullptr;
        int64_t chunk = 0;
        for (const auto& [key, c] : best)
          if (key.second == path && (!fastest || c.fwd > fastest->fwd))
            fastest = &c, chunk = key.first;
        if (!fastest) continue;
        const auto products = products_of(precisions[path]);
        const double limit = product_limit(products, chunk * scene.in.ref_images.size(0));
        const double points = fastest->fwd * fastest->fwd_s;
        for (const auto& [stage, sec, w, part] : stage_rows(fastest->profile, true)) {
          if (sec <= 0 || w.flops + w.bytes <= 0) continue;
          const double intensity = w.bytes > 0 ? w.flops / w.bytes : 0;
          const bool memory = intensity * bandwidth < limit;
          const double gflops = w.flops / sec / 1e9, gbytes = w.bytes / sec / 1e9;
          const double share = memory ? gbytes / bandwidth : gflops / limit;
          r.line("| " + precisions[path] + " | " + std::to_string(chunk) + " | " +
                 (part ? "&nbsp;&nbsp;" : "") + stage + " | " + fmt(w.flops / points / 1e3, 1) +
                 " | " + fmt(w.bytes / points, 0) + " | " + fmt(intensity, 2) + " | " +
                 fmt(sec / points * 1e9, 0) + " | " + fmt(gflops, 1) + " | " + fmt(gbytes, 1) +
                 " | " + fmt(limit, 1) + " | " + (memory ? "memory" : "products") + " | " +
                 fmt(100 * share, 0) + "% |");
        }
      }
      {
        model::Products onednn16, libtorch16;
        onednn16.precision = libtorch16.precision = model::Precision::bf16;
        onednn16.onednn = true;
        const int64_t rows = chunks.front() * scene.in.ref_images.size(0);
        r.line("");
        r.line("bf16 products of (" + std::to_string(rows) +
               ", 256) x (256, 256) in this run: oneDNN's inner-product primitive " +
               fmt(product_limit(onednn16, rows), 1) + " GFLOP/s" +
               (model::kernels::onednn_bf16() ? "" : " (not in this build: LibTorch's linear)") +
               ", LibTorch's bf16 linear " + fmt(product_limit(libtorch16, rows), 1) + " GFLOP/s.");
      }
      r.line("");
    }
  }

  // ---- training step and rendering, 64 and 16 samples -----------------------------------------
  for (const int samples : {64, 16})
    for (const auto& precision : precisions) {
      net->set_products(products_of(precision));
      RenderConfig rcs = rc;
      rcs.samples = samples;
      r.line("## " + std::to_string(samples) + " samples per ray, " + precision);
      r.line("");
      if (wanted("train")) {
        net->train();
        torch::manual_seed(2);
        const auto rays = patch_rays(scene);
        std::vector<torch::Tensor> snapshot;
        for (const auto& p : net->parameters()) snapshot.push_back(p.detach().clone());
        torch::optim::Adam adam(net->parameters(), torch::optim::AdamOptions(7e-4));
        int64_t evaluated = 0;
        auto step = [&](render::Profile* prof, bool skip_far_points) {
          net->set_profile(prof);
          render::ScopedTimer t(prof, "loss, optimiser");
          const auto cache = net->prepare(scene.in, rc.cull_distance);
          const auto img = pipeline::render(*net, cache, rays, rcs, {true, skip_far_points}, prof);
          evaluated = img.stats.density_points;
          const auto loss = (img.rgb - 0.5).pow(2).mean();
          adam.zero_grad();
          {
            render::ScopedTimer tb(prof, "backward");
            loss.backward();
          }
          adam.step();
          net->set_profile(nullptr);
        };
        step(nullptr, false);  // warm-up
        render::Profile prof;
        PeakMemory mem;
        const int reps = quick ? 1 : 3;
        double sec = 1e30;
        for (int i = 0; i < reps; ++i) {  // best of reps (shared machine)
          render::Profile p;
          const auto t0 = Clock::now();
          step(&p, false);
          const double s = seconds_since(t0);
          if (s < sec) sec = s, prof = p;
        }
        // The same step skipping samples farther than 0.1 m from the body (train.skip_far_points,
        // METHOD 9; off by default for parity).
        const auto t1 = Clock::now();
        step(nullptr, true);
        const double sec_skip = seconds_since(t1);
        const int64_t kept = evaluated;
        {
          torch::NoGradGuard ng;
          const auto params = net->parameters();
          for (size_t i = 0; i < params.size(); ++i) params[i].copy_(snapshot[i]);
        }
        r.line("Training step, best of " + std::to_string(reps) + " (" +
               std::to_string(rays.size()) + " rays x " + std::to_string(samples) +
               " samples = " + std::to_string(rays.size() * samples) + " points, chunk " +
               std::to_string(rcs.train_chunk_points) + ", checkpointed): " + fmt(sec, 2) +
               " s, peak memory " + mem.text() + ", " + fmt(rays.size() * samples / sec, 0) +
               " points/s end to end");
        shares(r, prof, sec);
        r.line("  with train.skip_far_points: " + fmt(sec_skip, 2) + " s (" + std::to_string(kept) +
               " of " + std::to_string(rays.size() * samples) + " points evaluated)");
        r.line("");
      }
      if (wanted("render")) {
        net->eval();
        const auto rays = box_rays(scene);
        render::Profile prof;
        PeakMemory mem;
        const auto t0 = Clock::now();
        render::RenderResult img;
        {
          torch::NoGradGuard ng;
          net->set_profile(&prof);
          const auto cache = net->prepare(scene.in, rc.cull_distance);
          img = pipeline::render(*net, cache, rays, rcs, pipeline::kInference, &prof);
          net->set_profile(nullptr);
        }
        const double sec = seconds_since(t0);
        const auto& st = img.stats;
        r.line("Render " + std::to_string(size) + "x" + std::to_string(size) +
               " (progressive, chunk " + std::to_string(rcs.chunk_points) + "): " + fmt(sec, 2) +
               " s, peak memory " + mem.text() + "; " + std::to_string(st.rays) + " in-box rays, " +
               std::to_string(st.points) + " samples, " + std::to_string(st.culled_points) +
               " culled (" + fmt(100.0 * st.culled_points / std::max<int64_t>(st.points, 1)) +
               "%), " + std::to_string(st.density_points) + " density, " +
               std::to_string(st.color_points) + " colour, " +
               std::to_string(st.terminated_points) + " skipped by early termination, " +
               std::to_string(st.empty_rays) + " empty rays; " + fmt(st.density_points / sec, 0) +
               " kept points/s end to end");
        shares(r, prof, sec);
        r.line("");
      }
    }
  r.line("Load average at the end: " + loadavg() + ".");
  if (!out.empty()) {
    std::ofstream f(out);
    f << r.md.str();
    std::cout << "written to " << out << std::endl;
  }
  return 0;
}

int main(int argc, char** argv) {
  return app::guarded_main("transhuman-bench-model", [&] { return run(argc, argv); });
}
