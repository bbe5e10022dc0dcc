// transhuman-train: trains TransHuman on a dataset named by the config (SPEC 5).
#include <spdlog/spdlog.h>

#include "app/app.hpp"
#include "app/summary.hpp"
#include "core/error.hpp"
#include "train/trainer.hpp"

int main(int argc, char** argv) {
  return th::app::guarded_main("transhuman-train", [&]() -> int {
    CLI::App cli{"Train TransHuman (generalizable neural human rendering)."};
    th::app::CommonOptions options;
    bool resume = false;
    int64_t max_steps = -1;
    th::app::add_common_options(cli, options);
    cli.add_flag("--resume", resume, "continue the run in --out from its latest checkpoint");
    cli.add_option("--max-steps", max_steps, "stop after this many steps in all (with a checkpoint)");
    CLI11_PARSE(cli, argc, argv);
    if (resume && options.out.empty()) th::fail("--resume needs --out (the run directory to continue)");

    const auto ctx = th::app::start_run(options, "transhuman-train",
                                        options.dry_run ? "" : "runs/train");
    th::app::print_summary(ctx);
    if (options.dry_run) return 0;
    const auto summary = th::train::train(ctx.config, ctx.device, {ctx.run_dir, resume, max_steps});
    spdlog::info("trained {} steps (epoch {}); last loss {:.4f}; checkpoint {}", summary.steps,
                 summary.epoch, summary.last_loss, summary.checkpoint.string());
    return 0;
  });
}
