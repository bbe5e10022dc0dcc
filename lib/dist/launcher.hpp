#pragma once
// transhuman-train --nproc N: N local worker processes of the same program, each told its place
// through the launcher environment (RANK, WORLD_SIZE, LOCAL_RANK, MASTER_ADDR, MASTER_PORT),
// supervised until they end. A worker that fails ends the run at once: the launcher stops the
// others (they could only report that it went away) and prints the failing worker's own error
// line last.

#include <string>
#include <vector>

namespace th::dist {

struct LaunchOptions {
  int nproc = 1;
  std::string master_addr = "127.0.0.1";
  int master_port = 0;     // 0: a free port on this machine
  double timeout_s = 300;  // how long the workers may take to stop after a forwarded signal
};

// Runs `args` (program path first) as `nproc` workers and waits for them. Returns 0 when every
// worker succeeded, otherwise the exit status of the first that failed (128 + signal when it was
// killed). The workers' stderr passes through the launcher line by line (rank 0's through a
// pseudo-terminal when the launcher's stderr is one), their error lines ("<program>: error: ...")
// held back: when a worker fails, the others are sent SIGTERM at once (SIGKILL 5 s later) and
// what they write from then on is dropped, and the failing worker's error line is printed last.
// `failure` (optional) receives "rank R exited with status S" (or "was killed by signal ...")
// when that worker printed no error line of its own, else "". Throws th::Error when a worker
// cannot be started. SIGTERM, SIGINT or SIGHUP to the launcher is passed to every worker and the
// launcher waits for them (returning 128 + that signal; after `timeout_s`, SIGTERM); a worker is
// sent SIGTERM when the launcher dies, even by SIGKILL (PR_SET_PDEATHSIG).
int launch_local(const std::vector<std::string>& args, const LaunchOptions& options,
                 std::string* failure = nullptr);

// The workers' command line for `transhuman-train --nproc N ...` (argc/argv as main got them):
// this executable with the same arguments, without --nproc N / --nproc=N, and with `--out OUT`
// first when `out` is not empty (so that every rank names the same run directory).
std::vector<std::string> worker_args(int argc, const char* const* argv, const std::string& out);

// A TCP port on 127.0.0.1 that is free now (bound and released).
int free_port();

// The path of the running executable (/proc/self/exe).
std::string self_executable();

}  // namespace th::dist
