// transhuman-train: trains TransHuman on a dataset named by the config (METHOD 5), in one process
// or data-parallel: --nproc N starts N local ranks, or a launcher sets RANK, WORLD_SIZE,
// LOCAL_RANK, MASTER_ADDR and MASTER_PORT for each copy of this program (several machines).
#include <spdlog/spdlog.h>

#include "app/app.hpp"
#include "app/ranks.hpp"
#include "app/summary.hpp"
#include "core/error.hpp"
#include "train/trainer.hpp"

int main(int argc, char** argv) {
  return th::app::guarded_main(th::app::rank_app_name("transhuman-train"), [&]() -> int {
    CLI::App cli{"Train TransHuman (generalizable neural human rendering)."};
    th::app::CommonOptions options;
    bool resume = false;
    int64_t max_steps = -1;
    int nproc = 0;
    std::string rank_state_dir, init_from;
    th::app::add_common_options(cli, options);
    th::app::add_force_option(cli, options);
    th::app::add_precision_option(cli, options);
    cli.add_flag("--resume", resume, "continue the run in --out from its latest checkpoint");
    cli.add_option("--max-steps", max_steps,
                   "stop after this many steps in all (with a checkpoint)")
        ->check(th::app::at_least(0));
    cli.add_option(
        "--init", init_from,
        "fine-tune: start from this checkpoint's weights (ours .pt or the reference's .pth), "
        "with a fresh optimiser and schedule");
    th::app::add_nproc_option(cli, nproc, "data-parallel training");
    cli.add_option("--rank-state", rank_state_dir,
                   "every rank writes its final state to DIR/rank<r>.pt")
        ->group("");  // for tests
    if (const auto rc = th::app::parse_command_line(cli, argc, argv)) return *rc;
    if (resume && options.out.empty())
      th::fail("--resume needs --out (the run directory to continue)");
    if (resume && options.force)
      th::fail("--resume continues the run in --out, --force replaces it: not both");
    if (resume && !init_from.empty())
      th::fail(
          "--resume continues the run in --out from its own checkpoint, --init starts one from "
          "another: not both");
    if (!init_from.empty())
      options.inputs.push_back({"the starting checkpoint (--init)", init_from});
    options.resume = resume;
    options.training = true;

    if (const auto code =
            th::app::launch_ranks(nproc, options, argc, argv, "transhuman-train", "runs/train"))
      return *code;

    const auto role = th::app::rank_role(options);
    const bool lead = role.lead;
    // --init is read whole before the run folder is written (a dry run reads it too).
    if (lead && !options.dry_run)
      options.preflight = [&init_from](const th::Config& config) {
        if (!init_from.empty()) th::train::check_init(config, init_from);
        th::app::load_first_training_sample(config);
      };
    const auto ctx = th::app::start_run(options, "transhuman-train",
                                        options.dry_run || !lead ? "" : "runs/train");
    th::app::share_cores(role, ctx);
    if (lead) th::app::print_summary(ctx, options.dry_run);
    if (options.dry_run) {
      if (!init_from.empty()) th::train::check_init(ctx.config, init_from);
      return 0;
    }

    th::train::TrainOptions train_options{ctx.run_dir, resume, max_steps};
    train_options.init_from = init_from;
    train_options.rank_state_dir = rank_state_dir;
    train_options.comm = th::app::join_ranks(role, ctx);
    const auto summary = th::train::train(ctx.config, ctx.device, train_options);
    spdlog::info("trained {} steps (epoch {}); last loss {:.4f}; checkpoint {}", summary.steps,
                 summary.epoch, summary.last_loss, summary.checkpoint.string());
    return 0;
  });
}
