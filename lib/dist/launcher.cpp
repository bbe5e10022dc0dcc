#include "dist/launcher.hpp"

#include <arpa/inet.h>
#include <netinet/in.h>
#include <signal.h>
#include <sys/prctl.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstring>
#include <filesystem>
#include <iostream>

extern char** environ;
#include <thread>

#include "core/error.hpp"

namespace th::dist {
namespace {

using Clock = std::chrono::steady_clock;

std::string describe(int status) {
  if (WIFEXITED(status)) return "exited with status " + std::to_string(WEXITSTATUS(status));
  if (WIFSIGNALED(status)) {
    const int sig = WTERMSIG(status);
    return "was killed by signal " + std::to_string(sig) + " (" + strsignal(sig) + ")";
  }
  return "ended with wait status " + std::to_string(status);
}

int exit_code(int status) {
  if (WIFEXITED(status)) return WEXITSTATUS(status);
  if (WIFSIGNALED(status)) return 128 + WTERMSIG(status);
  return 1;
}

}  // namespace

int free_port() {
  const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
  if (fd < 0) fail("cannot open a socket to find a free port: ", std::strerror(errno));
  sockaddr_in addr{};
  addr.sin_family = AF_INET;
  addr.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  addr.sin_port = 0;
  socklen_t len = sizeof addr;
  if (::bind(fd, reinterpret_cast<sockaddr*>(&addr), sizeof addr) != 0 ||
      ::getsockname(fd, reinterpret_cast<sockaddr*>(&addr), &len) != 0) {
    const std::string why = std::strerror(errno);
    ::close(fd);
    fail("cannot find a free port: ", why);
  }
  ::close(fd);
  return ntohs(addr.sin_port);
}

std::string self_executable() {
  std::error_code ec;
  const auto p = std::filesystem::read_symlink("/proc/self/exe", ec);
  if (ec) fail("cannot find the running executable (/proc/self/exe): ", ec.message());
  return p.string();
}

std::vector<std::string> worker_args(int argc, const char* const* argv, const std::string& out) {
  std::vector<std::string> args{self_executable()};
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--nproc") {
      ++i;  // and its value
      continue;
    }
    if (a.rfind("--nproc=", 0) == 0) continue;
    args.push_back(a);
  }
  if (!out.empty()) args.insert(args.begin() + 1, {"--out", out});
  return args;
}

namespace {

// The last SIGTERM, SIGINT or SIGHUP the launcher received (0: none), for forwarding.
volatile sig_atomic_t g_received = 0;
void remember_signal(int sig) { g_received = sig; }

// Installs remember_signal for the stop signals while the launcher waits (no SA_RESTART, so
// waitpid returns EINTR), and restores the previous handlers when it goes.
class ForwardSignals {
 public:
  ForwardSignals() {
    g_received = 0;
    struct sigaction sa {};
    sa.sa_handler = remember_signal;
    sigemptyset(&sa.sa_mask);
    for (size_t i = 0; i < std::size(kSignals); ++i) ::sigaction(kSignals[i], &sa, &previous_[i]);
  }
  ~ForwardSignals() {
    for (size_t i = 0; i < std::size(kSignals); ++i) ::sigaction(kSignals[i], &previous_[i], nullptr);
  }
  ForwardSignals(const ForwardSignals&) = delete;
  ForwardSignals& operator=(const ForwardSignals&) = delete;

 private:
  static constexpr int kSignals[] = {SIGTERM, SIGINT, SIGHUP};
  struct sigaction previous_[3];
};

}  // namespace

int launch_local(const std::vector<std::string>& args, const LaunchOptions& o) {
  if (args.empty()) fail("launch_local: no program");
  if (o.nproc < 1) fail("--nproc must be at least 1 (got ", o.nproc, ")");
  const int port = o.master_port > 0 ? o.master_port : free_port();

  std::vector<pid_t> pids(size_t(o.nproc), -1);
  auto terminate_all = [&](int sig) {
    for (pid_t p : pids)
      if (p > 0) ::kill(p, sig);
  };
  std::vector<char*> argv;
  for (const auto& a : args) argv.push_back(const_cast<char*>(a.c_str()));
  argv.push_back(nullptr);
  // A stop signal to the launcher goes to every rank, and the launcher waits for them.
  ForwardSignals forward;
  const pid_t launcher = ::getpid();
  for (int r = 0; r < o.nproc; ++r) {
    // The environment is built before fork: the child only calls async-signal-safe functions.
    std::vector<std::string> env_strings;
    const char* replaced[] = {"RANK=", "LOCAL_RANK=", "WORLD_SIZE=", "LOCAL_WORLD_SIZE=", "MASTER_ADDR=",
                              "MASTER_PORT="};
    for (char** e = environ; *e; ++e) {
      bool keep = true;
      for (const char* k : replaced) keep = keep && std::strncmp(*e, k, std::strlen(k)) != 0;
      if (keep) env_strings.emplace_back(*e);
    }
    env_strings.push_back("RANK=" + std::to_string(r));
    env_strings.push_back("LOCAL_RANK=" + std::to_string(r));
    env_strings.push_back("WORLD_SIZE=" + std::to_string(o.nproc));
    env_strings.push_back("LOCAL_WORLD_SIZE=" + std::to_string(o.nproc));
    env_strings.push_back("MASTER_ADDR=" + o.master_addr);
    env_strings.push_back("MASTER_PORT=" + std::to_string(port));
    std::vector<char*> envp;
    for (auto& e : env_strings) envp.push_back(e.data());
    envp.push_back(nullptr);
    const std::string exec_error = "cannot start worker " + std::to_string(r) + " (" + args[0] + ")\n";

    const pid_t pid = ::fork();
    if (pid < 0) {
      terminate_all(SIGKILL);
      fail("cannot start worker ", r, ": ", std::strerror(errno));
    }
    if (pid == 0) {
      // A rank dies with the launcher, also when the launcher is killed (SIGKILL) and cannot
      // forward anything; a launcher gone before this line is seen by getppid.
      ::prctl(PR_SET_PDEATHSIG, SIGTERM);
      if (::getppid() != launcher) ::_exit(128 + SIGTERM);
      // The handlers of the launcher do not survive execve; the signal mask and ignored
      // signals would, and none are set here.
      ::execve(argv[0], argv.data(), envp.data());
      (void)!::write(2, exec_error.data(), exec_error.size());
      ::_exit(127);
    }
    pids[size_t(r)] = pid;
  }

  int first_failure = 0, running = o.nproc, stopped_by = 0;
  Clock::time_point deadline;
  bool terminated = false;
  while (running > 0) {
    if (g_received && !stopped_by) {
      // Forwarded once; a rank still running after the timeout is terminated as after a failure.
      stopped_by = g_received;
      std::cerr << "launcher: " << strsignal(stopped_by) << ": passing it to the " << running
                << " running rank(s) and waiting for them" << std::endl;
      terminate_all(stopped_by);
      if (!first_failure) {
        first_failure = 128 + stopped_by;
        deadline = Clock::now() + std::chrono::milliseconds(int64_t(o.timeout_s * 1000) + 5000);
      }
    }
    int status = 0;
    const pid_t pid = ::waitpid(-1, &status, first_failure ? WNOHANG : 0);
    if (pid < 0) {
      if (errno == EINTR) continue;
      break;  // no children left
    }
    if (pid == 0) {  // after a failure: the others get the timeout to stop by themselves
      if (Clock::now() > deadline) {
        if (!terminated) {
          std::cerr << "launcher: the other workers did not stop within " << o.timeout_s
                    << " s after the failure; terminating them" << std::endl;
          terminate_all(SIGTERM);
          terminated = true;
          deadline = Clock::now() + std::chrono::seconds(5);
        } else {
          terminate_all(SIGKILL);
        }
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(50));
      continue;
    }
    int rank = -1;
    for (int r = 0; r < o.nproc; ++r)
      if (pids[size_t(r)] == pid) rank = r, pids[size_t(r)] = -1;
    if (rank < 0) continue;
    --running;
    const bool ok = WIFEXITED(status) && WEXITSTATUS(status) == 0;
    if (!ok && !(stopped_by && WIFSIGNALED(status) && WTERMSIG(status) == stopped_by)) {
      std::cerr << "launcher: rank " << rank << " " << describe(status) << std::endl;
      if (!first_failure) {
        first_failure = exit_code(status);
        deadline = Clock::now() + std::chrono::milliseconds(int64_t(o.timeout_s * 1000) + 5000);
      }
    }
  }
  return first_failure;
}

}  // namespace th::dist
