// transhuman-eval: evaluates a checkpoint with the protocol of SPEC.md section 6.
#include <spdlog/spdlog.h>

#include <iostream>

#include "app/app.hpp"
#include "app/summary.hpp"
#include "core/error.hpp"
#include "eval/evaluator.hpp"

int main(int argc, char** argv) {
  return th::app::guarded_main("transhuman-eval", [&]() -> int {
    CLI::App cli{"Evaluate a TransHuman checkpoint (PSNR, SSIM, LPIPS) with the paper's protocol."};
    th::app::CommonOptions options;
    std::string checkpoint, setting;
    int limit = -1;
    th::app::add_common_options(cli, options);
    cli.add_option("--checkpoint", checkpoint, "checkpoint: ours (.pt) or the reference's (.pth)");
    cli.add_option("--setting", setting, "split setting (pose, identity, one_shot, cross_dataset, fitting)");
    cli.add_option("--limit", limit, "evaluate only the first N images (quick look)");
    CLI11_PARSE(cli, argc, argv);
    if (limit >= 0) options.overrides.push_back("eval.limit=" + std::to_string(limit));
    if (!setting.empty()) options.overrides.push_back("eval.setting=" + setting);
    if (!options.dry_run && checkpoint.empty()) th::fail("--checkpoint is required");

    const auto ctx = th::app::start_run(options, "transhuman-eval", options.dry_run ? "" : "runs/eval");
    th::app::print_summary(ctx);
    if (options.dry_run) return 0;
    const auto summary = th::eval::evaluate(ctx.config, ctx.device, checkpoint, ctx.run_dir);
    std::cout << th::eval::markdown_table({summary});
    return 0;
  });
}
