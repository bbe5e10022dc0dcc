// transhuman-train: trains TransHuman on a dataset named by the config (SPEC 5), in one process
// or data-parallel: --nproc N starts N local ranks, or a launcher sets RANK, WORLD_SIZE,
// LOCAL_RANK, MASTER_ADDR and MASTER_PORT for each copy of this program (several machines).
#include <spdlog/spdlog.h>

#include <cstdlib>
#include <cstring>
#include <iostream>
#include <thread>

#include "app/app.hpp"
#include "app/summary.hpp"
#include "core/error.hpp"
#include "core/runtime.hpp"
#include "dist/communicator.hpp"
#include "dist/launcher.hpp"
#include "train/trainer.hpp"

namespace {

std::string app_name() {
  const char* rank = std::getenv("RANK");
  const char* world = std::getenv("WORLD_SIZE");
  return rank && world ? std::string("transhuman-train[rank ") + rank + "]" : "transhuman-train";
}

}  // namespace

int main(int argc, char** argv) {
  return th::app::guarded_main(app_name(), [&]() -> int {
    CLI::App cli{"Train TransHuman (generalizable neural human rendering)."};
    th::app::CommonOptions options;
    bool resume = false;
    int64_t max_steps = -1;
    int nproc = 0;
    std::string rank_state_dir;
    th::app::add_common_options(cli, options);
    th::app::add_force_option(cli, options);
    th::app::add_precision_option(cli, options);
    cli.add_flag("--resume", resume, "continue the run in --out from its latest checkpoint");
    cli.add_option("--max-steps", max_steps, "stop after this many steps in all (with a checkpoint)")
        ->check(th::app::at_least(0));
    cli.add_option("--nproc", nproc, "data-parallel training with this many local worker processes (at most 8 "
                                     "per core)")
        ->check(th::app::in_range(1, 1024));
    cli.add_option("--rank-state", rank_state_dir, "every rank writes its final state to DIR/rank<r>.pt")
        ->group("");  // for tests
    if (const auto rc = th::app::parse_command_line(cli, argc, argv)) return *rc;
    if (resume && options.out.empty()) th::fail("--resume needs --out (the run directory to continue)");
    if (resume && options.force) th::fail("--resume continues the run in --out, --force replaces it: not both");
    options.resume = resume;

    if (nproc > 1 && !options.dry_run) {
      if (std::getenv("WORLD_SIZE"))
        th::fail("--nproc starts the ranks itself; it cannot be used inside a launcher (WORLD_SIZE is set)");
      const int cores = int(std::max(1u, std::thread::hardware_concurrency()));
      if (nproc > 8 * cores)
        th::fail("--nproc ", nproc, " is more than 8 ranks per core (this machine has ", cores, "); at most ", 8 * cores);
      const auto config = th::config::load<th::Config>(options.config, options.overrides);
      th::dist::LaunchOptions launch;
      launch.nproc = nproc;
      launch.timeout_s = config.train.dist_timeout_s;
      const int code = th::dist::launch_local(th::dist::worker_args(argc, argv, options.out.empty() ? "runs/train" : ""), launch);
      if (code != 0) std::cerr << "transhuman-train: error: a rank failed (see above)" << std::endl;
      return code;
    }

    const auto env = th::dist::environment_from_env();
    const bool distributed = env && env->world_size > 1;
    const bool lead = !distributed || env->rank == 0;
    if (!lead) {
      options.quiet = true;  // one voice: rank 0 logs, the others report errors only
      options.out.clear();   // and write nothing
    }
    if (lead && !options.dry_run) options.preflight = th::app::load_first_training_sample;
    const auto ctx = th::app::start_run(options, "transhuman-train",
                                        options.dry_run || !lead ? "" : "runs/train");
    if (distributed && ctx.config.threads == 0) {
      // "One per core" is shared among the ranks of this machine (LOCAL_WORLD_SIZE, set by
      // --nproc and torchrun), so they do not oversubscribe the cores.
      const char* local = std::getenv("LOCAL_WORLD_SIZE");
      const int ranks_here = local ? std::max(1, std::atoi(local)) : 1;
      const int cores = int(std::max(1u, std::thread::hardware_concurrency()));
      th::runtime::set_threads(std::max(1, cores / ranks_here));
    }
    if (lead) th::app::print_summary(ctx, options.dry_run);
    if (options.dry_run) return 0;

    th::train::TrainOptions train_options{ctx.run_dir, resume, max_steps};
    train_options.rank_state_dir = rank_state_dir;
    if (distributed)
      train_options.comm = std::make_shared<th::dist::Communicator>(
          *env, th::dist::resolve_backend(ctx.config.train.dist_backend, ctx.device), ctx.device,
          ctx.config.train.dist_timeout_s, ctx.config.train.dist_bucket_mb);
    const auto summary = th::train::train(ctx.config, ctx.device, train_options);
    spdlog::info("trained {} steps (epoch {}); last loss {:.4f}; checkpoint {}", summary.steps,
                 summary.epoch, summary.last_loss, summary.checkpoint.string());
    return 0;
  });
}
