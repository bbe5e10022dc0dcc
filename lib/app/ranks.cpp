#include "app/ranks.hpp"

#include <cstdlib>
#include <iostream>
#include <thread>

#include "core/config_io.hpp"
#include "core/error.hpp"
#include "core/runtime.hpp"
#include "dist/communicator.hpp"
#include "dist/launcher.hpp"

namespace th::app {

void add_nproc_option(CLI::App& cli, int& nproc, const std::string& what) {
  cli.add_option("--nproc", nproc,
                 what + " over this many local worker processes (at most 8 per core)")
      ->check(in_range(1, 1024));
}

std::string rank_app_name(const std::string& app) {
  const char* rank = std::getenv("RANK");
  const char* world = std::getenv("WORLD_SIZE");
  return rank && world ? app + "[rank " + rank + "]" : app;
}

std::optional<int> launch_ranks(int nproc, const CommonOptions& options, int argc, char** argv,
                                const std::string& app, const std::string& default_out) {
  if (nproc <= 1 || options.dry_run) return std::nullopt;
  if (std::getenv("WORLD_SIZE"))
    fail(
        "--nproc starts the ranks itself; it cannot be used inside a launcher (WORLD_SIZE is set)");
  const int cores = int(std::max(1u, std::thread::hardware_concurrency()));
  if (nproc > 8 * cores)
    fail("--nproc ", nproc, " is more than 8 ranks per core (this machine has ", cores,
         "); at most ", 8 * cores);
  const auto config = config::load<Config>(options.config, options.overrides);
  dist::LaunchOptions launch;
  launch.nproc = nproc;
  launch.timeout_s = config.train.dist_timeout_s;
  // The failing rank's own error line ends the output; a rank that died without one is named here.
  std::string failure;
  const int code = dist::launch_local(
      dist::worker_args(argc, argv, options.out.empty() ? default_out : ""), launch, &failure);
  if (code != 0 && !failure.empty()) std::cerr << app << ": error: " << failure << std::endl;
  return code;
}

RankRole rank_role(CommonOptions& options) {
  RankRole role;
  const auto env = dist::environment_from_env();
  if (!env || env->world_size <= 1) return role;
  role.distributed = true;
  role.rank = env->rank;
  role.world_size = env->world_size;
  role.lead = env->rank == 0;
  if (!role.lead) {
    options.quiet = true;  // one voice: rank 0 logs, the others report errors only
    options.out.clear();   // and write nothing
  }
  return role;
}

void share_cores(const RankRole& role, const RunContext& ctx) {
  if (!role.distributed || ctx.config.threads != 0) return;
  const int cores = int(std::max(1u, std::thread::hardware_concurrency()));
  runtime::set_threads(std::max(1, cores / dist::environment_from_env()->local_world_size));
}

std::shared_ptr<dist::Communicator> join_ranks(const RankRole& role, const RunContext& ctx) {
  if (!role.distributed) return nullptr;
  const auto env = dist::environment_from_env();
  return std::make_shared<dist::Communicator>(
      *env, dist::resolve_backend(ctx.config.train.dist_backend, ctx.device), ctx.device,
      ctx.config.train.dist_timeout_s, ctx.config.train.dist_bucket_mb);
}

}  // namespace th::app
