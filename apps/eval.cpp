// transhuman-eval: evaluates a checkpoint with the protocol of METHOD 6, in one process or over
// several ranks (--nproc N here, or a launcher's RANK, WORLD_SIZE, MASTER_ADDR, MASTER_PORT on
// several machines): the views are split by frame and rank 0 writes what one process writes.
#include <spdlog/spdlog.h>

#include <iostream>

#include "app/app.hpp"
#include "app/ranks.hpp"
#include "app/summary.hpp"
#include "eval/evaluator.hpp"
#include "report/report.hpp"

int main(int argc, char** argv) {
  return th::app::guarded_main(th::app::rank_app_name("transhuman-eval"), [&]() -> int {
    CLI::App cli{"Evaluate a TransHuman checkpoint (PSNR, SSIM, LPIPS) with the paper's protocol."};
    th::app::CommonOptions options;
    th::app::ModelOptions model;
    int limit = -1;
    int nproc = 0;
    th::app::add_common_options(cli, options);
    th::app::add_model_options(cli, model);
    th::app::add_precision_option(cli, options);
    th::app::add_force_option(cli, options);
    cli.add_option("--limit", limit, "evaluate only the first N images (quick look)")
        ->check(th::app::at_least(0));
    th::app::add_nproc_option(cli, nproc, "split the views");
    if (const auto rc = th::app::parse_command_line(cli, argc, argv)) return *rc;
    if (limit >= 0) options.overrides.push_back("eval.limit=" + std::to_string(limit));
    th::app::apply_model_options(model, options);
    options.scoring = true;

    if (const auto code =
            th::app::launch_ranks(nproc, options, argc, argv, "transhuman-eval", "runs/eval"))
      return *code;
    const auto role = th::app::rank_role(options);
    const auto ctx = th::app::start_run(options, "transhuman-eval",
                                        options.dry_run || !role.lead ? "" : "runs/eval");
    th::app::share_cores(role, ctx);
    if (role.lead) th::app::print_summary(ctx, options.dry_run, model.checkpoint);
    if (options.dry_run) return 0;
    const auto comm = th::app::join_ranks(role, ctx);
    const auto summary =
        th::eval::evaluate(ctx.config, ctx.device, model.checkpoint, ctx.run_dir, comm.get());
    if (!role.lead) return 0;
    std::cout << th::eval::markdown_table({summary});
    // The page beside the outputs; with the training curve when the checkpoint lies in a
    // training run's checkpoints/ folder.
    th::report::PageSources page;
    page.title = "TransHuman evaluation: " + summary.setting;
    page.evals = {ctx.run_dir};
    const auto metrics =
        std::filesystem::path(model.checkpoint).parent_path().parent_path() / "metrics.jsonl";
    if (std::filesystem::exists(metrics)) page.metrics = metrics;
    std::cout << "report: " << th::report::write_page(page, ctx.run_dir).string() << "\n";
    return 0;
  });
}
