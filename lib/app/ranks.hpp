#pragma once
// Several processes of one command (transhuman-train, -eval, -render): `--nproc N` starts N
// local ranks of the same program, or a launcher (torchrun, SLURM, by hand) sets RANK,
// WORLD_SIZE, LOCAL_RANK, MASTER_ADDR and MASTER_PORT for each copy on each machine. Rank 0
// writes the run folder and logs; the others compute and report errors only.

#include <CLI/CLI.hpp>
#include <memory>
#include <optional>
#include <string>

#include "app/app.hpp"

namespace th::dist {
class Communicator;
}

namespace th::app {

// Registers --nproc on `cli` (`what` says what the ranks share: "data-parallel training").
void add_nproc_option(CLI::App& cli, int& nproc, const std::string& what);

// "transhuman-eval[rank 1]" inside a launcher (RANK and WORLD_SIZE set), else `app`.
std::string rank_app_name(const std::string& app);

// With --nproc N > 1 (and not a dry run): starts N local ranks of this program with the same
// arguments (and the same --out, `default_out` when none was given), waits for them and
// returns the exit code. The first rank to fail ends the others at once, and its error line
// ("transhuman-train[rank 0]: error: ...") is the last line printed. nullopt when this process
// is to do the work itself. Refuses --nproc inside a launcher, and more than 8 ranks per core.
std::optional<int> launch_ranks(int nproc, const CommonOptions& options, int argc, char** argv,
                                const std::string& app, const std::string& default_out);

// Where this process stands, read from the launcher environment before start_run: a rank
// other than 0 is made quiet and writes nothing (its --out is cleared).
struct RankRole {
  bool distributed = false;
  bool lead = true;
  int rank = 0, world_size = 1;
};
RankRole rank_role(CommonOptions& options);

// After start_run, in a distributed run where `threads` is 0 (one per core): shares this
// machine's cores among its ranks (LOCAL_WORLD_SIZE, set by --nproc and torchrun).
void share_cores(const RankRole& role, const RunContext& ctx);

// Joins the other ranks (the c10d rendezvous at MASTER_ADDR:MASTER_PORT, train.dist_backend,
// train.dist_timeout_s). nullptr when this process runs alone.
std::shared_ptr<dist::Communicator> join_ranks(const RankRole& role, const RunContext& ctx);

}  // namespace th::app
