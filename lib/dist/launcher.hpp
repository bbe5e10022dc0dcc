#pragma once
// transhuman-train --nproc N: N local worker processes of the same program, each told its place
// through the launcher environment (RANK, WORLD_SIZE, LOCAL_RANK, MASTER_ADDR, MASTER_PORT),
// supervised until they end. A worker that fails makes the launcher give the others the timeout
// to notice and stop on their own, then terminate them: it never waits forever.

#include <string>
#include <vector>

namespace th::dist {

struct LaunchOptions {
  int nproc = 1;
  std::string master_addr = "127.0.0.1";
  int master_port = 0;     // 0: a free port on this machine
  double timeout_s = 300;  // how long the others may take to stop after one failed
};

// Runs `args` (program path first) as `nproc` workers and waits for them. Returns 0 when every
// worker succeeded, otherwise the exit status of the first that failed (128 + signal when it was
// killed); reports each failure on stderr. Throws th::Error when a worker cannot be started.
// SIGTERM, SIGINT or SIGHUP to the launcher is passed to every worker and the launcher waits for
// them (returning 128 + that signal); a worker is sent SIGTERM when the launcher dies, even by
// SIGKILL (PR_SET_PDEATHSIG).
int launch_local(const std::vector<std::string>& args, const LaunchOptions& options);

// The workers' command line for `transhuman-train --nproc N ...` (argc/argv as main got them):
// this executable with the same arguments, without --nproc N / --nproc=N, and with `--out OUT`
// first when `out` is not empty (so that every rank names the same run directory).
std::vector<std::string> worker_args(int argc, const char* const* argv, const std::string& out);

// A TCP port on 127.0.0.1 that is free now (bound and released).
int free_port();

// The path of the running executable (/proc/self/exe).
std::string self_executable();

}  // namespace th::dist
