// transhuman-eval: evaluates a checkpoint with the protocol of SPEC.md section 6.
#include <spdlog/spdlog.h>

#include "app/app.hpp"
#include "app/summary.hpp"
#include "core/error.hpp"

int main(int argc, char** argv) {
  return th::app::guarded_main("transhuman-eval", [&]() -> int {
    CLI::App cli{"Evaluate a TransHuman checkpoint (PSNR, SSIM, LPIPS)."};
    th::app::CommonOptions options;
    std::string checkpoint;
    int limit = -1;
    th::app::add_common_options(cli, options);
    cli.add_option("--checkpoint", checkpoint, "checkpoint to evaluate (ours or a reference .pth)");
    cli.add_option("--limit", limit, "evaluate only the first N images (quick look)");
    CLI11_PARSE(cli, argc, argv);
    if (limit >= 0) options.overrides.push_back("eval.limit=" + std::to_string(limit));

    const auto ctx = th::app::start_run(options, "transhuman-eval");
    th::app::print_summary(ctx);
    if (options.dry_run) return 0;
    th::fail("evaluation is not available in this build yet (tracked in issue 6); use --dry-run");
  });
}
