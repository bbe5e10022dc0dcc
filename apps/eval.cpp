// transhuman-eval: evaluates a checkpoint with the protocol of METHOD 6, in one process or over
// several ranks (--nproc N here, or a launcher's RANK, WORLD_SIZE, MASTER_ADDR, MASTER_PORT on
// several machines): the views are split by frame and rank 0 writes what one process writes.
#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include <iostream>

#include "app/app.hpp"
#include "app/ranks.hpp"
#include "app/summary.hpp"
#include "core/runtime.hpp"
#include "eval/evaluator.hpp"
#include "report/report.hpp"

int main(int argc, char** argv) {
  return th::app::guarded_main(th::app::rank_app_name("transhuman-eval"), [&]() -> int {
    CLI::App cli{"Evaluate a TransHuman checkpoint (PSNR, SSIM, LPIPS) with the paper's protocol."};
    th::app::CommonOptions options;
    th::app::ModelOptions model;
    int limit = -1;
    int nproc = 0;
    bool baked = false, resume = false;
    double bake_voxel = 0.02;
    th::app::add_common_options(cli, options);
    th::app::add_model_options(cli, model);
    th::app::add_precision_option(cli, options);
    th::app::add_force_option(cli, options);
    cli.add_option("--limit", limit, "evaluate only the first N images (quick look)")
        ->check(th::app::at_least(0));
    th::app::add_nproc_option(cli, nproc, "split the views");
    cli.add_flag("--baked", baked,
                 "render the views from bakes of their frames (METHOD 7.1): one bake per frame "
                 "serves all its views; an approximate score, marked as such (eval.renderer)");
    auto* voxel = cli.add_option("--bake-voxel", bake_voxel,
                                 "the bakes' grid spacing in metres (default 0.02; with --baked; "
                                 "eval.bake_voxel)")
                      ->check(th::app::in_range(0.001, 0.2));
    cli.add_flag("--resume", resume,
                 "continue the evaluation in --out: the views its rows.jsonl holds are kept "
                 "(the same checkpoint, renderer and settings only)");
    if (const auto rc = th::app::parse_command_line(cli, argc, argv)) return *rc;
    if (*voxel && !baked) th::fail("--bake-voxel sets the grid of the bakes: it needs --baked");
    if (resume && options.out.empty())
      th::fail("--resume needs --out (the evaluation folder to continue)");
    if (resume && options.force)
      th::fail("--resume continues the evaluation in --out, --force replaces it: not both");
    options.resume = resume;
    // Rows of another request are refused before the folder's config.yaml and log are written.
    if (resume)
      options.preflight = [&](const th::Config& c) {
        th::eval::check_resume(c, th::runtime::select_device(c.device), model.checkpoint,
                               options.out);
      };
    if (baked) options.overrides.push_back("eval.renderer=baked");
    if (*voxel) options.overrides.push_back("eval.bake_voxel=" + fmt::format("{}", bake_voxel));
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
    const auto summary = th::eval::evaluate(ctx.config, ctx.device, model.checkpoint, ctx.run_dir,
                                            comm.get(), resume);
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
