// Data-parallel training benchmark (lib/dist): samples/s of transhuman-train with 1 process and
// with 2 processes (--nproc 2) on the same configuration, the gradient all-reduce time per step
// of those runs, and the all-reduce of the paper model's gradients (default config) between 2
// processes over loopback Gloo.
//   transhuman-bench-dist --data DIR [--config FILE] [--steps N] [--out FILE] [--force]
// DIR: a synthetic dataset (transhuman-synth; e.g. build/test_tmp/synth_tiny). Timings exclude
// the first `--warmup` steps of each run (start-up, first allocations).
#include <torch/torch.h>

#include <CLI/CLI.hpp>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <ctime>
#include <fstream>
#include <iomanip>
#include <iostream>
#include <nlohmann/json.hpp>
#include <sstream>
#include <thread>

#include "app/app.hpp"
#include "common.hpp"
#include "core/error.hpp"
#include "core/process.hpp"
#include "dist/communicator.hpp"
#include "dist/launcher.hpp"
#include "model/transhuman.hpp"

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

namespace {

std::string fmt(double v, int prec = 2) {
  std::ostringstream s;
  s << std::fixed << std::setprecision(prec) << v;
  return s.str();
}

// A number of one metrics.jsonl row; NaN when the row lacks it (or holds null).
double field(const nlohmann::json& row, const std::string& key) {
  const auto it = row.find(key);
  return it != row.end() && it->is_number() ? it->get<double>() : NAN;
}

struct RunFigures {
  double wall_s = 0, step_s = 0, samples_per_s = 0, allreduce_s = NAN;
  int global_batch = 0;
};

// Runs transhuman-train and averages its per-step metrics after the warm-up steps.
RunFigures train_run(const std::string& exe, const std::string& label,
                     const std::vector<std::string>& extra, const std::string& config,
                     const fs::path& data, const fs::path& out, int steps, int warmup) {
  fs::remove_all(out);
  std::vector<std::string> args{exe,           "--config",           config, "--out", out.string(),
                                "--max-steps", std::to_string(steps)};
  args.insert(args.end(), extra.begin(), extra.end());
  for (const std::string& o :
       {"data.root=" + data.string(), "data.split_file=" + (data / "split.yaml").string(),
        "model.grouping.cache_dir=" + (data.parent_path() / "kmeans_cache").string(),
        std::string("train.val_views=0"), std::string("train.log_every_steps=1"),
        std::string("train.epochs=1000")})
    args.push_back(o);
  std::cout << label << ": " << std::flush;
  const auto t0 = Clock::now();
  const int rc = th::run_program(args, out.string() + ".log");
  RunFigures f;
  f.wall_s = std::chrono::duration<double>(Clock::now() - t0).count();
  if (rc != 0) th::fail(label, " failed (", rc, "); see ", out.string(), ".log");
  std::ifstream in(out / "metrics.jsonl");
  std::string line;
  int n = 0;
  double ar = 0;
  while (std::getline(in, line)) {
    const auto row = nlohmann::json::parse(line, nullptr, /*allow_exceptions=*/false);
    if (!row.is_object() || field(row, "step") <= warmup) continue;
    f.step_s += field(row, "time_per_step");
    f.global_batch = int(field(row, "global_batch"));
    ar += field(row, "allreduce_seconds");  // NaN without ranks
    ++n;
  }
  if (n == 0) th::fail(label, ": no steps after the warm-up in ", (out / "metrics.jsonl").string());
  f.step_s /= n;
  f.allreduce_s = ar / n;
  f.samples_per_s = f.global_batch / f.step_s;
  std::cout << fmt(f.samples_per_s) << " samples/s (" << fmt(f.step_s * 1000, 0) << " ms/step)"
            << std::endl;
  return f;
}

// Worker of the all-reduce measurement: the gradients of the default model, averaged `reps` times.
int allreduce_worker(int reps, const std::string& result) {
  const auto env = th::dist::environment_from_env();
  if (!env) th::fail("--allreduce-worker runs under the launcher");
  torch::set_num_threads(1);
  th::Config config;
  th::model::TransHuman model(config.model);
  int64_t numel = 0;
  for (auto& p : model->parameters()) {
    p.mutable_grad() = torch::randn_like(p);
    numel += p.numel();
  }
  th::dist::Communicator comm(*env, "gloo", torch::kCPU, 60, config.train.dist_bucket_mb);
  std::vector<double> times;
  for (int i = 0; i < reps + 2; ++i) {
    comm.barrier("bench");
    comm.average_gradients(model->parameters(), comm.world_size());
    if (i >= 2) times.push_back(comm.allreduce_seconds_last());
  }
  if (comm.rank() == 0) {
    std::sort(times.begin(), times.end());
    std::ofstream(result) << numel << " " << times[times.size() / 2] << " " << times.front()
                          << "\n";
  }
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  return th::app::guarded_main("transhuman-bench-dist", [&]() -> int {
    CLI::App cli{"Data-parallel training benchmark"};
    std::string data, config = "tests/configs/tiny_train.yaml", out = "bench/results/dist.md",
                      result;
    int steps = 20, warmup = 3, reps = 10;
    // Built next to this program: build/bench/.. -> build/apps/transhuman-train.
    std::string train_exe = (fs::path(th::dist::self_executable()).parent_path().parent_path() /
                             "apps" / "transhuman-train")
                                .string();
    bool worker = false, force = false;
    cli.add_option("--data", data, "synthetic dataset folder (e.g. build/test_tmp/synth_tiny)");
    cli.add_option("--config", config, "training config")->capture_default_str();
    cli.add_option("--steps", steps, "training steps per run")->capture_default_str();
    cli.add_option("--warmup", warmup, "steps left out of the timings")->capture_default_str();
    cli.add_option("--reps", reps, "all-reduce repetitions")->capture_default_str();
    cli.add_option("--out", out, "write the figures to this file (markdown; empty: print only)")
        ->capture_default_str();
    cli.add_flag("--force", force, "replace --out when it exists");
    cli.add_option("--train-exe", train_exe, "transhuman-train to run")->capture_default_str();
    cli.add_flag("--allreduce-worker", worker)->group("");
    cli.add_option("--result", result)->group("");
    if (const auto rc = th::app::parse_command_line(cli, argc, argv)) return *rc;
    if (worker) return allreduce_worker(reps, result);
    if (data.empty() || !fs::is_directory(data)) th::fail("--data '", data, "' is not a folder");
    th::bench::refuse_overwriting(out, force);

    const fs::path tmp = fs::temp_directory_path() / "transhuman_bench_dist";
    fs::create_directories(tmp);
    const auto one1 = train_run(train_exe, "1 process, 1 thread", {"--threads", "1"}, config, data,
                                tmp / "p1t1", steps, warmup);
    const auto one2 = train_run(train_exe, "1 process, 2 threads", {"--threads", "2"}, config, data,
                                tmp / "p1t2", steps, warmup);
    const auto two =
        train_run(train_exe, "2 processes, 1 thread each", {"--nproc", "2", "--threads", "1"},
                  config, data, tmp / "p2", steps, warmup);

    std::cout << "all-reduce of the default model's gradients, 2 processes: " << std::flush;
    const std::string result_file = (tmp / "allreduce.txt").string();
    th::dist::LaunchOptions lo;
    lo.nproc = 2;
    lo.timeout_s = 60;
    if (th::dist::launch_local({th::dist::self_executable(), "--allreduce-worker", "--reps",
                                std::to_string(reps), "--result", result_file},
                               lo) != 0)
      th::fail("the all-reduce workers failed");
    int64_t numel = 0;
    double median = 0, best = 0;
    std::ifstream(result_file) >> numel >> median >> best;
    std::cout << fmt(median * 1000, 1) << " ms" << std::endl;

    std::ostringstream md;
    const std::time_t now = std::time(nullptr);
    char date[32];
    std::strftime(date, sizeof date, "%Y-%m-%d %H:%M", std::localtime(&now));
    md << "# Data-parallel training (transhuman-bench-dist, " << date << ")\n\n"
       << "Machine: " << std::thread::hardware_concurrency()
       << " CPU cores, Gloo over loopback. Config " << config << " (val off), " << steps
       << " steps per run, the first " << warmup
       << " left out; time per step as rank 0 measures it (it includes waiting for the other "
          "rank).\n\n"
       << "| run | global batch | ms / step | samples / s | all-reduce ms / step | wall s (incl. "
          "start-up) |\n"
       << "|---|---|---|---|---|---|\n";
    auto row = [&](const std::string& name, const RunFigures& f) {
      md << "| " << name << " | " << f.global_batch << " | " << fmt(f.step_s * 1000, 0) << " | "
         << fmt(f.samples_per_s) << " | "
         << (std::isnan(f.allreduce_s) ? "-" : fmt(f.allreduce_s * 1000, 2)) << " | "
         << fmt(f.wall_s, 1) << " |\n";
    };
    row("1 process, 1 thread", one1);
    row("1 process, 2 threads", one2);
    row("2 processes (--nproc 2), 1 thread each", two);
    md << "\nThe all-reduce time of a training step is measured from the call to the averaged "
          "gradients, so it "
       << "includes waiting for the slower rank, not only the transfer. On this machine the 2 "
          "ranks and their "
       << "loader threads share 2 cores: no speed-up is expected, and none is claimed.\n";
    md << "\nAll-reduce (sum + divide, " << th::TrainConfig{}.dist_bucket_mb
       << " MB buckets) of the default model's gradients (" << numel
       << " float32 = " << fmt(numel * 4 / 1048576.0, 1) << " MiB) between 2 processes: median "
       << fmt(median * 1000, 1) << " ms, best " << fmt(best * 1000, 1) << " ms (" << reps
       << " repetitions).\n";
    std::cout << "\n" << md.str();
    if (!out.empty()) {
      std::ofstream(out) << md.str();
      std::cout << "written to " << out << std::endl;
    }
    return 0;
  });
}
