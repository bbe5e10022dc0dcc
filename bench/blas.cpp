// BLAS benchmark: the matrix shapes TransHuman spends its time on, timed through LibTorch with
// its own OpenMP threads. Used to choose between OpenBLAS's pthread and OpenMP flavours.
//   transhuman-bench-blas [--threads N] [--out FILE]
#include <ATen/Parallel.h>
#include <torch/torch.h>

#include <CLI/CLI.hpp>
#include <chrono>
#include <fstream>
#include <iostream>
#include <sstream>

#include "app/app.hpp"
#include "core/runtime.hpp"

namespace {

struct Case {
  const char* name;
  int64_t m, k, n;
  int batch;
};

double time_case(const Case& c, int reps) {
  auto a = torch::randn({c.batch, c.m, c.k});
  auto b = torch::randn({c.batch, c.k, c.n});
  (void)torch::bmm(a, b);  // warm-up
  const auto t0 = std::chrono::steady_clock::now();
  for (int i = 0; i < reps; ++i) (void)torch::bmm(a, b);
  const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return 2.0 * c.batch * c.m * c.k * c.n * reps / s / 1e9;  // GFLOP/s
}

}  // namespace

int run(int argc, char** argv) {
  CLI::App cli{"BLAS throughput on TransHuman's matrix shapes"};
  int threads = 0;
  std::string out;
  cli.add_option("--threads", threads, "LibTorch threads (0: one per core)");
  cli.add_option("--out", out, "append the figures to this file");
  if (const auto rc = th::app::parse_command_line(cli, argc, argv)) return *rc;
  th::runtime::set_threads(threads);
  torch::NoGradGuard no_grad;
  torch::manual_seed(0);

  const auto blas = th::runtime::detect_blas();
  const Case cases[] = {
      {"point heads, 65536 x 384 -> 256", 65536, 384, 256, 1},
      {"point heads, 9600 x 256 -> 256", 9600, 256, 256, 1},
      {"ViT qkv, 3 x 300 x 192 -> 576", 300, 192, 576, 3},
      {"ViT MLP, 3 x 300 x 768 -> 192", 300, 768, 192, 3},
      {"attention scores, 9 x 300 x 64 -> 300", 300, 64, 300, 9},
  };
  std::ostringstream report;
  report << "BLAS: " << blas.name << " [" << blas.details << "] (" << blas.library << "), "
         << torch::get_num_threads() << " LibTorch threads\n";
  double total = 0;
  for (const auto& c : cases) {
    const double gflops = time_case(c, c.m > 1000 ? 5 : 200);
    total += gflops;
    char line[160];
    std::snprintf(line, sizeof line, "  %-42s %8.1f GFLOP/s\n", c.name, gflops);
    report << line;
  }
  report << "  mean " << total / std::size(cases) << " GFLOP/s\n";
  std::cout << report.str();
  if (!out.empty()) std::ofstream(out, std::ios::app) << report.str() << "\n";
  return 0;
}

int main(int argc, char** argv) {
  return th::app::guarded_main("transhuman-bench-blas", [&] { return run(argc, argv); });
}
