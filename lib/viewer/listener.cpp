#include "viewer/listener.hpp"

#include <netdb.h>
#include <netinet/in.h>
#include <poll.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cstring>
#include <optional>

#include "core/error.hpp"

namespace th::viewer {
namespace {

using Clock = std::chrono::steady_clock;

// The connection the calling handler thread serves (-1 outside a handler), and whether it is to
// be closed after the response.
thread_local int t_socket = -1;
thread_local bool t_close_after = false;

// Waits until `sock` is ready for `events`, `stopping` is set, or `deadline` passes (in short
// slices, so that a stop is seen at once). True when ready.
bool wait_for(int sock, short events, Clock::time_point deadline,
              const std::atomic<bool>& stopping) {
  while (!stopping.load()) {
    const auto left =
        std::chrono::duration_cast<std::chrono::milliseconds>(deadline - Clock::now()).count();
    if (left <= 0) return false;
    pollfd p{sock, events, 0};
    const int n = ::poll(&p, 1, int(std::min<long long>(left, 50)));
    if (n > 0) return true;  // ready, or hung up / failed: the read or write says which
    if (n < 0 && errno != EINTR) return false;
  }
  return false;
}

// One connection's byte stream for httplib's request parser and response writer, with the
// deadlines of Listener: reads fail past the request's deadline, writes past the response's.
class ConnectionStream final : public httplib::Stream {
 public:
  ConnectionStream(int sock, const std::atomic<bool>& stopping)
      : sock_(sock), stopping_(stopping) {}

  // Waits for the next request's first byte: true when one came within `idle`.
  bool wait_request(std::chrono::seconds idle) {
    return begin_ < end_ || wait_for(sock_, POLLIN, Clock::now() + idle, stopping_);
  }
  void begin_request() {
    read_deadline_ = Clock::now() + std::chrono::seconds(Listener::kRequestSeconds);
    write_deadline_.reset();
  }

  bool is_readable() const override {
    return begin_ < end_ || wait_for(sock_, POLLIN, read_deadline_, stopping_);
  }
  bool is_writable() const override {
    return wait_for(sock_, POLLOUT, write_deadline(), never_stop_);
  }

  // True when a request did not arrive whole in time: the connection is closed after the answer.
  bool read_failed() const { return read_failed_; }

  ssize_t read(char* ptr, size_t size) override {
    if (begin_ == end_) {
      if (!wait_for(sock_, POLLIN, read_deadline_, stopping_)) {
        read_failed_ = true;
        return -1;
      }
      const ssize_t n = ::recv(sock_, buffer_, sizeof(buffer_), MSG_DONTWAIT);
      if (n <= 0) return n == 0 ? 0 : -1;
      begin_ = 0;
      end_ = size_t(n);
    }
    const size_t n = std::min(size, end_ - begin_);
    std::memcpy(ptr, buffer_ + begin_, n);
    begin_ += n;
    return ssize_t(n);
  }

  // Sends what the socket takes now (httplib calls again for the rest); a response is written
  // also while stopping (its client then learns why), within its deadline.
  ssize_t write(const char* ptr, size_t size) override {
    if (!write_deadline_)
      write_deadline_ = Clock::now() + std::chrono::seconds(Listener::kWriteSeconds);
    if (!wait_for(sock_, POLLOUT, write_deadline(), never_stop_)) return -1;
    const ssize_t n = ::send(sock_, ptr, size, MSG_NOSIGNAL | MSG_DONTWAIT);
    return n < 0 && (errno == EAGAIN || errno == EWOULDBLOCK) ? 0 : n;
  }

  void get_remote_ip_and_port(std::string& ip, int& port) const override {
    name(::getpeername, ip, port);
  }
  void get_local_ip_and_port(std::string& ip, int& port) const override {
    name(::getsockname, ip, port);
  }
  socket_t socket() const override { return sock_; }

 private:
  Clock::time_point write_deadline() const {
    // While stopping, a response gets a second at most.
    const auto deadline =
        write_deadline_.value_or(Clock::now() + std::chrono::seconds(Listener::kWriteSeconds));
    return stopping_.load() ? std::min(deadline, Clock::now() + std::chrono::seconds(1)) : deadline;
  }

  void name(int (*get)(int, sockaddr*, socklen_t*), std::string& ip, int& port) const {
    sockaddr_storage address{};
    socklen_t length = sizeof(address);
    port = -1;
    ip.clear();
    if (get(sock_, reinterpret_cast<sockaddr*>(&address), &length) == 0)
      ip = numeric_address(address, &port);
  }

  int sock_;
  const std::atomic<bool>& stopping_;
  const std::atomic<bool> never_stop_{false};
  char buffer_[4096];
  size_t begin_ = 0, end_ = 0;
  bool read_failed_ = false;
  Clock::time_point read_deadline_ = Clock::now();
  std::optional<Clock::time_point> write_deadline_;
};

// Reads and drops what the client still sends, briefly, so that closing the socket does not
// reset the connection before the client has read the answer (a refused upload).
void drain(int sock) {
  const auto until = Clock::now() + std::chrono::milliseconds(500);
  const std::atomic<bool> never{false};
  char buffer[16384];
  size_t dropped = 0;
  while (dropped < (size_t{4} << 20) && wait_for(sock, POLLIN, until, never)) {
    const ssize_t n = ::recv(sock, buffer, sizeof(buffer), MSG_DONTWAIT);
    if (n <= 0) break;
    dropped += size_t(n);
  }
}

}  // namespace

std::string numeric_address(const sockaddr_storage& address, int* port) {
  char host[NI_MAXHOST] = "", service[NI_MAXSERV] = "";
  const socklen_t length =
      address.ss_family == AF_INET6 ? sizeof(sockaddr_in6) : sizeof(sockaddr_in);
  if (::getnameinfo(reinterpret_cast<const sockaddr*>(&address), length, host, sizeof(host),
                    service, sizeof(service), NI_NUMERICHOST | NI_NUMERICSERV) != 0)
    return "";
  if (port) *port = std::atoi(service);
  return host;
}

Listener::Listener() {
  new_task_queue = [] { return new httplib::ThreadPool(kThreads); };
  // Exclusive: SO_REUSEADDR lets the viewer restart at once on a port whose old connections
  // linger, and still refuses a second listener.
  set_socket_options([](socket_t sock) {
    const int yes = 1;
    ::setsockopt(sock, SOL_SOCKET, SO_REUSEADDR, &yes, sizeof(yes));
  });
  // No Nagle delay: an answer's headers and body go out as separate writes, and on a kept-alive
  // connection the body would wait for the client's delayed acknowledgement (about 40 ms).
  set_tcp_nodelay(true);
  set_read_timeout(kRequestSeconds);
  set_write_timeout(kWriteSeconds);
  set_keep_alive_timeout(kIdleSeconds);
  set_keep_alive_max_count(kRequestsPerConnection);
  set_payload_max_length(4096);  // the API takes queries; bodies are refused before reading
}

void Listener::bind(const std::string& host, int port) {
  errno = 0;
  if (bind_to_port(host, port)) return;
  const int error = errno;
  const std::string where =
      (host.find(':') != std::string::npos ? "[" + host + "]" : host) + ":" + std::to_string(port);
  if (error == EADDRINUSE)
    fail("cannot listen on ", where, ": port ", port,
         " is in use (another viewer or program listens there);",
         " stop it or choose another --port");
  if (error == EACCES)
    fail("cannot listen on ", where, ": port ", port,
         " needs privileges; choose a --port above 1023");
  if (error == EADDRNOTAVAIL)
    fail("cannot listen on ", where, ": '", host, "' is not an address of this machine");
  fail("cannot listen on ", where,
       error ? ": " + std::string(std::strerror(error)) : std::string(": unknown host"));
}

sockaddr_storage Listener::bound_address() const {
  sockaddr_storage address{};
  socklen_t length = sizeof(address);
  ::getsockname(svr_sock_, reinterpret_cast<sockaddr*>(&address), &length);
  return address;
}

bool Listener::ipv6_only() const {
  int only = 0;
  socklen_t length = sizeof(only);
  return ::getsockopt(svr_sock_, IPPROTO_IPV6, IPV6_V6ONLY, &only, &length) == 0 && only != 0;
}

void Listener::shut_down() {
  stopping_ = true;
  stop();
}

bool Listener::client_gone() {
  if (t_socket < 0) return false;
  pollfd p{t_socket, POLLIN | POLLRDHUP, 0};
  if (::poll(&p, 1, 0) <= 0) return false;
  if (p.revents & (POLLHUP | POLLERR | POLLRDHUP)) return true;
  char byte = 0;
  return (p.revents & POLLIN) && ::recv(t_socket, &byte, 1, MSG_PEEK | MSG_DONTWAIT) == 0;
}

void Listener::close_after_response() { t_close_after = true; }

bool Listener::process_and_close_socket(socket_t sock) {
  ConnectionStream stream(sock, stopping_);
  bool ok = true, drain_first = false;
  for (size_t count = kRequestsPerConnection; count > 0 && !stopping_; --count) {
    if (!stream.wait_request(std::chrono::seconds(kIdleSeconds))) break;
    stream.begin_request();
    t_socket = sock;
    t_close_after = false;
    bool closed = false;
    ok = process_request(stream, count == 1 || stopping_, closed, nullptr);
    t_socket = -1;
    drain_first = t_close_after;
    if (!ok || closed || t_close_after || stream.read_failed()) break;
  }
  ::shutdown(sock, SHUT_WR);
  if (drain_first) drain(sock);
  ::shutdown(sock, SHUT_RDWR);
  ::close(sock);
  return ok;
}

}  // namespace th::viewer
