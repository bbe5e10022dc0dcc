// Reader benchmark: parsing a pickle that holds SMPL's largest array (posedirs, 6890 x 3 x 207
// float64, 34 MB) against copying the same bytes once. The reader moves array data straight
// into the tensor, so the two should be close; tests/io checks what it reads, this how fast.
//   transhuman-bench-io [--runs N] [--out FILE]
#include <torch/torch.h>

#include <CLI/CLI.hpp>
#include <algorithm>
#include <chrono>
#include <fstream>
#include <iostream>
#include <sstream>

#include "app/app.hpp"
#include "io/pickle.hpp"

namespace {

template <class F>
double best_seconds(int runs, F&& f) {
  double best = 1e30;
  for (int run = 0; run < runs; ++run) {
    const auto t0 = std::chrono::steady_clock::now();
    f();
    best = std::min(best,
                    std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
  }
  return best;
}

}  // namespace

int run(int argc, char** argv) {
  CLI::App cli{"Pickle reader throughput on SMPL's posedirs"};
  int runs = 5;
  std::string out = "bench/results/io.md";
  cli.add_option("--runs", runs, "timed runs (the best is reported)")->check(CLI::Range(1, 1000));
  cli.add_option("--out", out, "append the figures to this file (empty: print only)");
  if (const auto rc = th::app::parse_command_line(cli, argc, argv)) return *rc;

  using th::io::Value;
  const auto posedirs = torch::arange(6890 * 3 * 207, torch::kDouble).reshape({6890, 3, 207});
  std::ostringstream report;
  for (int protocol : {2, 4}) {
    const std::string bytes = th::io::pickle_bytes(
        Value::dict({{Value::str("posedirs"), Value::array(posedirs)}}), protocol);
    Value parsed;
    const double parse =
        best_seconds(runs, [&] { parsed = th::io::parse_pickle(bytes, "posedirs.pkl"); });
    if (!torch::equal(parsed["posedirs"].as_tensor(), posedirs)) {
      std::cerr << "transhuman-bench-io: error: the parsed array differs from the written one\n";
      return 1;
    }
    // The baseline allocates as well: fresh pages cost about as much as the copy itself.
    const double copy = best_seconds(runs, [&] {
      std::string c(bytes);
      if (c.size() != bytes.size()) std::abort();
    });
    char line[200];
    std::snprintf(
        line, sizeof line,
        "pickle protocol %d, %.1f MB: parse %.2f ms, one copy %.2f ms (%.2fx), best of %d\n",
        protocol, bytes.size() / 1e6, parse * 1e3, copy * 1e3, parse / copy, runs);
    report << line;
  }
  std::cout << report.str();
  if (!out.empty()) std::ofstream(out, std::ios::app) << report.str() << "\n";
  return 0;
}

int main(int argc, char** argv) {
  return th::app::guarded_main("transhuman-bench-io", [&] { return run(argc, argv); });
}
