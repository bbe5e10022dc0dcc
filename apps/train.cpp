// transhuman-train: trains TransHuman on a dataset named by the config.
#include <spdlog/spdlog.h>

#include "app/app.hpp"
#include "app/summary.hpp"
#include "core/error.hpp"

int main(int argc, char** argv) {
  return th::app::guarded_main("transhuman-train", [&]() -> int {
    CLI::App cli{"Train TransHuman (generalizable neural human rendering)."};
    th::app::CommonOptions options;
    bool resume = false;
    th::app::add_common_options(cli, options);
    cli.add_flag("--resume", resume, "continue the run in --out from its latest checkpoint");
    CLI11_PARSE(cli, argc, argv);

    const auto ctx = th::app::start_run(options, "transhuman-train");
    th::app::print_summary(ctx);
    if (options.dry_run) return 0;
    th::fail("training is not available in this build yet (tracked in issue 6); use --dry-run");
  });
}
