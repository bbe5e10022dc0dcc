#pragma once
// Rank processes for the distributed tests: transhuman-train started with the launcher
// environment, output to a log file, waited for with a deadline.

#include <fcntl.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <optional>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "support/test_env.hpp"

namespace th::test {

inline std::filesystem::path train_executable() {
  return build_dir() / "apps" / "transhuman-train";
}

struct Process {
  pid_t pid = -1;
  std::filesystem::path log;
};

// Starts `args` (program first) with `env` added to this process's environment; stdout and
// stderr go to `log`.
inline Process spawn(const std::vector<std::string>& args, const std::vector<std::string>& env,
                     const std::filesystem::path& log) {
  std::vector<char*> argv, envp;
  for (const auto& a : args) argv.push_back(const_cast<char*>(a.c_str()));
  argv.push_back(nullptr);
  // Ours first so getenv finds them before any inherited value of the same name.
  for (const auto& e : env) envp.push_back(const_cast<char*>(e.c_str()));
  for (char** e = environ; *e; ++e) envp.push_back(*e);
  envp.push_back(nullptr);
  const std::string log_path = log.string();
  const pid_t pid = ::fork();
  if (pid == 0) {
    const int fd = ::open(log_path.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    if (fd >= 0) {
      ::dup2(fd, 1);
      ::dup2(fd, 2);
    }
    ::execve(argv[0], argv.data(), envp.data());
    // Into the log: the test prints it, and "exit 127" alone says nothing.
    const std::string why =
        std::string("cannot run ") + argv[0] + ": " + std::strerror(errno) + "\n";
    (void)!::write(2, why.data(), why.size());
    ::_exit(127);
  }
  return {pid, log};
}

// The wait status of `p` once it has ended, or nullopt after `seconds`.
inline std::optional<int> wait_for(const Process& p, double seconds) {
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::duration<double>(seconds);
  for (;;) {
    int status = 0;
    const pid_t r = ::waitpid(p.pid, &status, WNOHANG);
    if (r == p.pid) return status;
    if (r < 0) return std::nullopt;
    if (std::chrono::steady_clock::now() > deadline) return std::nullopt;
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
}

// Kills `p` (if still running) and reaps it.
inline void kill_and_reap(const Process& p) {
  if (p.pid <= 0) return;
  ::kill(p.pid, SIGKILL);
  int status = 0;
  ::waitpid(p.pid, &status, 0);
}

inline std::string read_text(const std::filesystem::path& file) {
  std::ifstream in(file);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

}  // namespace th::test
