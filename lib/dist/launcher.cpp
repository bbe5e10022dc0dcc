#include "dist/launcher.hpp"

#include <arpa/inet.h>
#include <fcntl.h>
#include <netinet/in.h>
#include <poll.h>
#include <signal.h>
#include <sys/prctl.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <termios.h>
#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <chrono>
#include <cstring>
#include <filesystem>
#include <iostream>
#include <thread>

extern char** environ;

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
    for (size_t i = 0; i < std::size(kSignals); ++i)
      ::sigaction(kSignals[i], &previous_[i], nullptr);
  }
  ForwardSignals(const ForwardSignals&) = delete;
  ForwardSignals& operator=(const ForwardSignals&) = delete;

 private:
  static constexpr int kSignals[] = {SIGTERM, SIGINT, SIGHUP};
  struct sigaction previous_[3];
};

}  // namespace

namespace {

// Where a rank's stderr goes: a pipe, or a pseudo-terminal for rank 0 when the launcher's own
// stderr is a terminal (its progress bar then draws as in one process). `read` is the launcher's
// end, `write` the rank's.
struct ErrorChannel {
  int read = -1, write = -1;
};

ErrorChannel open_channel(bool terminal) {
  ErrorChannel c;
  if (terminal) {
    const int master = ::posix_openpt(O_RDWR | O_NOCTTY | O_CLOEXEC);
    const char* name = master >= 0 && ::grantpt(master) == 0 && ::unlockpt(master) == 0
                           ? ::ptsname(master)
                           : nullptr;
    const int slave = name ? ::open(name, O_RDWR | O_NOCTTY | O_CLOEXEC) : -1;
    if (slave >= 0) {
      termios t{};
      if (::tcgetattr(slave, &t) == 0) {
        t.c_oflag &= ~tcflag_t(OPOST);  // the bytes as written: no "\n" -> "\r\n"
        ::tcsetattr(slave, TCSANOW, &t);
      }
      c.read = master;
      c.write = slave;
    } else if (master >= 0) {
      ::close(master);
    }
  }
  if (c.read < 0) {
    int fds[2];
    if (::pipe2(fds, O_CLOEXEC) != 0)
      fail("cannot make a pipe for a worker's output: ", std::strerror(errno));
    c.read = fds[0];
    c.write = fds[1];
  }
  ::fcntl(c.read, F_SETFL, ::fcntl(c.read, F_GETFL) | O_NONBLOCK);
  return c;
}

void write_all(int fd, const std::string& text) {
  for (size_t done = 0; done < text.size();) {
    const ssize_t n = ::write(fd, text.data() + done, text.size() - done);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) return;
    done += size_t(n);
  }
}

// "<program>[rank R]: error: ..." or "...: internal error: ..." (guarded_main's last line): the
// line a failing rank ends with.
bool is_error_line(const std::string& line) {
  for (const char* mark : {": error: ", ": internal error: "}) {
    const size_t at = line.find(mark);
    if (at == std::string::npos || at == 0) continue;
    std::string program = line.substr(0, at);
    if (program.back() == ']' && program.find('[') != std::string::npos)
      program.erase(program.rfind('['));
    if (!program.empty() && program.find(' ') == std::string::npos) return true;
  }
  return false;
}

// An error that reports another rank, as the communicator words them (communicator.cpp): "rank R
// of N: <collective> failed: ..." (a peer went away or hung), "rank 0 failed during ...", "rank
// R of N failed during ..." or "... sent no result ...". The error that caused them is another
// rank's own.
bool reports_another_rank(const std::string& line) {
  size_t at = line.find(": error: ");
  if (at == std::string::npos) return false;
  const std::string message = line.substr(at + 9);
  if (message.rfind("rank ", 0) != 0) return false;
  at = message.find_first_not_of("0123456789", 5);
  if (at == 5 || at == std::string::npos) return false;
  const std::string rest = message.substr(at);
  return rest.rfind(" failed during ", 0) == 0 ||
         (rest.rfind(" of ", 0) == 0 && rest.size() > 4 && std::isdigit((unsigned char)rest[4]));
}

// One rank's stderr on its way to the launcher's: lines pass through as they come, but its
// error lines are held, so that the error that ends the run can be printed last.
struct Relay {
  int fd = -1;  // -1 once at its end
  std::string partial;
  std::vector<std::string> held;
  // When (counted in lines received from every rank, `clock`) it first held an error of its
  // own, not one that reports another rank; -1: none.
  int64_t own_error = -1;
  int64_t* clock = nullptr;
  bool muted = false;  // stopped by the launcher: what it says now is the stop, not news

  void take(const char* data, size_t n) {
    partial.append(data, n);
    size_t start = 0;
    for (size_t end; (end = partial.find('\n', start)) != std::string::npos; start = end + 1) {
      std::string line = partial.substr(start, end + 1 - start);
      ++*clock;
      if (is_error_line(line)) {
        if (own_error < 0 && !reports_another_rank(line)) own_error = *clock;
        held.push_back(std::move(line));
      } else if (!muted) {
        write_all(2, line);
      }
    }
    partial.erase(0, start);
    // A progress bar redraws its line after "\r" without ending it: shown as it comes.
    if (!partial.empty() && partial[0] == '\r') {
      if (!muted) write_all(2, partial);
      partial.clear();
    }
  }
  // Reads what is there; false at the end (the rank and everything it started closed it).
  bool pump() {
    char buf[4096];
    for (;;) {
      const ssize_t n = ::read(fd, buf, sizeof buf);
      if (n > 0) {
        take(buf, size_t(n));
        continue;
      }
      if (n < 0 && errno == EINTR) continue;
      if (n < 0 && (errno == EAGAIN || errno == EWOULDBLOCK)) return true;
      // 0: end of a pipe; EIO: a pseudo-terminal whose other end is closed.
      if (!partial.empty()) take("\n", 1);
      ::close(fd);
      fd = -1;
      return false;
    }
  }
  void release() {
    for (const auto& line : held) write_all(2, line);
    held.clear();
  }
};

}  // namespace

int launch_local(const std::vector<std::string>& args, const LaunchOptions& o,
                 std::string* failure) {
  if (args.empty()) fail("launch_local: no program");
  if (o.nproc < 1) fail("--nproc must be at least 1 (got ", o.nproc, ")");
  const int port = o.master_port > 0 ? o.master_port : free_port();

  std::vector<pid_t> pids(size_t(o.nproc), -1);
  std::vector<Relay> relays(size_t(o.nproc));
  int64_t lines_received = 0;
  for (auto& relay : relays) relay.clock = &lines_received;
  auto terminate_all = [&](int sig) {
    for (pid_t p : pids)
      if (p > 0) ::kill(p, sig);
  };
  auto close_relays = [&] {
    for (auto& r : relays)
      if (r.fd >= 0) ::close(r.fd), r.fd = -1;
  };
  std::vector<char*> argv;
  for (const auto& a : args) argv.push_back(const_cast<char*>(a.c_str()));
  argv.push_back(nullptr);
  const bool terminal = ::isatty(2) != 0;
  // A stop signal to the launcher goes to every rank, and the launcher waits for them.
  ForwardSignals forward;
  const pid_t launcher = ::getpid();
  for (int r = 0; r < o.nproc; ++r) {
    // The environment is built before fork: the child only calls async-signal-safe functions.
    std::vector<std::string> env_strings;
    const char* replaced[] = {
        "RANK=", "LOCAL_RANK=", "WORLD_SIZE=", "LOCAL_WORLD_SIZE=", "MASTER_ADDR=", "MASTER_PORT="};
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
    const std::string exec_error =
        "cannot start worker " + std::to_string(r) + " (" + args[0] + ")\n";
    ErrorChannel channel;
    try {
      channel = open_channel(terminal && r == 0);
    } catch (...) {
      terminate_all(SIGKILL);
      close_relays();
      throw;
    }

    const pid_t pid = ::fork();
    if (pid < 0) {
      terminate_all(SIGKILL);
      close_relays();
      ::close(channel.read);
      ::close(channel.write);
      fail("cannot start worker ", r, ": ", std::strerror(errno));
    }
    if (pid == 0) {
      // A rank dies with the launcher, also when the launcher is killed (SIGKILL) and cannot
      // forward anything; a launcher gone before this line is seen by getppid.
      ::prctl(PR_SET_PDEATHSIG, SIGTERM);
      if (::getppid() != launcher) ::_exit(128 + SIGTERM);
      ::dup2(channel.write, 2);  // every other descriptor of the channels closes on exec
      // The handlers of the launcher do not survive execve; the signal mask and ignored
      // signals would, and none are set here.
      ::execve(argv[0], argv.data(), envp.data());
      (void)!::write(2, exec_error.data(), exec_error.size());
      ::_exit(127);
    }
    ::close(channel.write);
    relays[size_t(r)].fd = channel.read;
    pids[size_t(r)] = pid;
  }

  // The first rank that fails ends the run: the others are stopped (what they would report now
  // is that it went away), and its own error line is the last line printed. A rank whose error
  // only reports another rank (its connection to a failing rank 0 closed) may end before the
  // rank that caused it has printed why: then the ranks get a few seconds to show an error of
  // their own, which is the one reported.
  int first_failure = 0, running = o.nproc, stopped_by = 0, chosen = -1;
  std::vector<int> failed;                         // ranks that failed on their own, in order
  std::vector<int> statuses(size_t(o.nproc), -1);  // wait status of the ranks that ended
  std::string chosen_how;
  Clock::time_point deadline, grace;
  bool terminated = false;
  auto how = [&](int r) {
    return "rank " + std::to_string(r) + " " +
           (statuses[size_t(r)] >= 0 ? describe(statuses[size_t(r)]) : "failed");
  };
  // The rank whose error ends the run: the earliest error of a rank's own (once that rank has
  // ended, or when `now`), else the first rank that failed. -1: not yet.
  auto pick = [&](bool now) {
    int best = -1;
    for (int r = 0; r < o.nproc; ++r) {
      const Relay& relay = relays[size_t(r)];
      if (relay.own_error >= 0 && (best < 0 || relay.own_error < relays[size_t(best)].own_error))
        best = r;
    }
    if (best >= 0 && (now || pids[size_t(best)] < 0)) return best;
    return now && !failed.empty() ? failed.front() : -1;
  };
  for (;;) {
    if (g_received && !stopped_by) {
      // Forwarded once; a rank still running after the timeout is terminated, then killed.
      stopped_by = g_received;
      std::cerr << "launcher: " << strsignal(stopped_by) << ": passing it to the " << running
                << " running rank(s) and waiting for them" << std::endl;
      terminate_all(stopped_by);
      if (!first_failure) {
        first_failure = 128 + stopped_by;
        deadline = Clock::now() + std::chrono::milliseconds(int64_t(o.timeout_s * 1000) + 5000);
      }
    }
    // What the ranks wrote, as it comes (a short wait: exits are polled below).
    std::vector<pollfd> fds;
    std::vector<size_t> which;
    for (size_t r = 0; r < relays.size(); ++r)
      if (relays[r].fd >= 0) {
        fds.push_back({relays[r].fd, POLLIN, 0});
        which.push_back(r);
      }
    if (running == 0 && fds.empty()) break;
    if (!fds.empty()) {
      if (::poll(fds.data(), fds.size(), running > 0 ? 50 : 1000) > 0) {
        for (size_t i = 0; i < fds.size(); ++i)
          if (fds[i].revents) relays[which[i]].pump();
      } else if (running == 0) {
        close_relays();  // the ranks are gone; something they started still holds their output
      }
    } else {
      std::this_thread::sleep_for(std::chrono::milliseconds(50));
    }
    // The ranks that ended since, lowest rank first.
    std::vector<std::pair<int, int>> ended;  // rank, status
    for (int status = 0;;) {
      const pid_t pid = ::waitpid(-1, &status, WNOHANG);
      if (pid <= 0) break;
      for (int r = 0; r < o.nproc; ++r)
        if (pids[size_t(r)] == pid) {
          pids[size_t(r)] = -1;
          statuses[size_t(r)] = status;
          --running;
          ended.emplace_back(r, status);
        }
    }
    std::sort(ended.begin(), ended.end());
    for (const auto& [rank, status] : ended) {
      Relay& relay = relays[size_t(rank)];
      if (relay.fd >= 0) relay.pump();  // what it wrote before it ended
      const bool ok = WIFEXITED(status) && WEXITSTATUS(status) == 0;
      const bool stopped =
          (stopped_by && WIFSIGNALED(status) && WTERMSIG(status) == stopped_by) || relay.muted;
      if (ok || stopped) {
        if (!relay.muted) relay.release();
        continue;
      }
      if (failed.empty()) grace = Clock::now() + std::chrono::seconds(3);
      failed.push_back(rank);
    }
    if (chosen < 0 && !failed.empty()) {
      chosen = pick(running == 0 || Clock::now() > grace);
      if (chosen >= 0) {
        chosen_how = how(chosen);
        const int status = statuses[size_t(chosen)] >= 0 ? statuses[size_t(chosen)]
                                                         : statuses[size_t(failed.front())];
        if (!first_failure) first_failure = exit_code(status);
        for (int r = 0; r < o.nproc; ++r)
          if (r != chosen) relays[size_t(r)].muted = true;
        if (running > 0) {
          std::cerr << "launcher: " << chosen_how << "; stopping the other rank(s)" << std::endl;
          for (int r = 0; r < o.nproc; ++r)
            if (r != chosen && pids[size_t(r)] > 0) ::kill(pids[size_t(r)], SIGTERM);
          deadline = Clock::now() + std::chrono::seconds(5);
          terminated = true;
        }
      }
    }
    // Ranks that outlive their stop: after a forwarded signal, the timeout and then SIGTERM; after
    // SIGTERM, five seconds and then SIGKILL.
    if ((chosen >= 0 || stopped_by) && running > 0 && Clock::now() > deadline) {
      if (!terminated) {
        std::cerr << "launcher: the ranks did not stop within " << o.timeout_s
                  << " s; terminating them" << std::endl;
        terminate_all(SIGTERM);
        terminated = true;
      } else {
        terminate_all(SIGKILL);
      }
      deadline = Clock::now() + std::chrono::seconds(5);
    }
  }
  if (chosen >= 0) {
    for (const int r : failed)
      if (r != chosen)
        std::cerr << "launcher: " << how(r) << " too; the error that ended the run is rank "
                  << chosen << "'s:" << std::endl;
    Relay& relay = relays[size_t(chosen)];
    const bool said = !relay.held.empty();
    relay.release();  // its own words, last
    if (failure) *failure = said ? "" : how(chosen);
  }
  return first_failure;
}

}  // namespace th::dist
