// Training-loader throughput: samples per second of data::Dataset + Prefetcher on the dataset a
// config names (by default the synthetic data), with 0 (synchronous), 1 and 2 worker threads.
//   transhuman-bench-loader [--config FILE] [--samples N] [--out FILE] [overrides...]
#include <spdlog/spdlog.h>

#include <CLI/CLI.hpp>
#include <chrono>
#include <fstream>
#include <iostream>
#include <numeric>
#include <random>
#include <sstream>

#include "app/app.hpp"
#include "body/smpl.hpp"
#include "data/dataset.hpp"

int main(int argc, char** argv) {
  return th::app::guarded_main("transhuman-bench-loader", [&]() -> int {
    CLI::App cli{"Training loader throughput"};
    th::app::CommonOptions options;
    int samples = 40;
    std::string out = "bench/results/loader.md";
    th::app::add_common_options(cli, options);
    cli.add_option("--samples", samples, "samples per measurement");
    cli.add_option("--results", out, "append the figures to this markdown file");
    if (const auto rc = th::app::parse_command_line(cli, argc, argv)) return *rc;
    const auto ctx = th::app::start_run(options, "transhuman-bench-loader");
    const auto& data = ctx.config.data;

    auto dataset = std::make_shared<const th::data::Dataset>(
        data, data.train_setting, th::data::Dataset::Mode::Train, th::data::load_body_model(data));
    std::mt19937_64 rng(1);
    std::vector<size_t> order(static_cast<size_t>(samples));
    for (auto& o : order) o = std::uniform_int_distribution<size_t>(0, dataset->size() - 1)(rng);
    std::vector<uint64_t> seeds(order.size());
    std::iota(seeds.begin(), seeds.end(), 100);

    std::ostringstream report;
    const auto first = dataset->load(order[0], 0);
    report << "Training loader, " << data.root << " (" << data.train_setting << ", ratio "
           << data.ratio << ", reference images " << first.ref_images.sizes() << ", "
           << first.ray_o.size(0) << " rays/sample), " << samples << " samples:\n";
    for (size_t i = 0; i < std::min<size_t>(order.size(), 8); ++i)
      dataset->load(order[i], 0);  // warm the file cache
    for (int workers : {0, 1, 2}) {
      th::data::Prefetcher prefetcher(dataset, order, seeds, workers, 8);
      const auto t0 = std::chrono::steady_clock::now();
      while (!prefetcher.done()) prefetcher.next();
      const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
      char line[128];
      std::snprintf(line, sizeof line, "  %d worker thread(s): %6.2f samples/s\n", workers,
                    samples / s);
      report << line;
    }
    std::cout << report.str();
    std::ofstream(out, std::ios::app) << report.str() << "\n";
    return 0;
  });
}
