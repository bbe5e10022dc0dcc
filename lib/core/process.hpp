#pragma once
// Running another program without a shell: its arguments are passed as they are, so no path,
// name or value a user gave is ever read as shell code.

#include <string>
#include <vector>

namespace th {

// Runs `args` (the program first: a path, or a name looked up on PATH) and waits for it.
// stdout and stderr go to `log_file` when it is not empty (created or truncated), else to ours.
// Returns its exit status, 128 + the signal when a signal ended it. Throws th::Error naming the
// program when it cannot be started, or the log file when it cannot be opened.
int run_program(const std::vector<std::string>& args, const std::string& log_file = "");

}  // namespace th
