#pragma once
// The viewer's connections, served as a server on a shared machine must serve them. cpp-httplib
// parses requests and routes them; this subclass owns the socket of each connection so that:
//   - the port is the viewer's alone (SO_REUSEADDR only: httplib's default SO_REUSEPORT lets a
//     second process listen on the same port and take half the requests);
//   - a request must arrive whole within a deadline, and idle connections are closed after a
//     few seconds, so slow or idle clients hold a thread for a bounded time (and there are
//     threads enough for many of them);
//   - a handler can ask whether its client has gone away (to cancel work nobody will read);
//   - stop() ends every connection within a fraction of a second, whatever its clients do.
// Private to lib/viewer (it needs <httplib.h>).

#include <httplib.h>
#include <sys/socket.h>

#include <atomic>
#include <string>

namespace th::viewer {

class Listener : public httplib::Server {
 public:
  // Limits of one connection.
  static constexpr int kThreads = 64;         // connections served at once
  static constexpr int kRequestSeconds = 10;  // request line and headers, whole
  static constexpr int kIdleSeconds = 5;      // between requests on one connection
  static constexpr int kWriteSeconds = 30;    // one response, whole
  static constexpr size_t kRequestsPerConnection = 100;

  Listener();

  // Binds host:port exclusively. Throws th::Error naming the address and the reason (a port
  // in use, an address not of this machine, a port that needs privileges).
  void bind(const std::string& host, int port);
  // The bound address as getsockname reports it.
  sockaddr_storage bound_address() const;
  // For an IPv6 socket: true when it takes IPv6 clients only (IPV6_V6ONLY).
  bool ipv6_only() const;

  // Ends every connection and run(); callable from any thread, also before listening.
  void shut_down();

  // In a handler: true once this request's client has closed its connection.
  static bool client_gone();
  // In a handler: close the connection after this response (its body was not read).
  static void close_after_response();

 private:
  bool process_and_close_socket(socket_t sock) override;

  std::atomic<bool> stopping_{false};
};

// "127.0.0.1", "::1": the numeric address of `address`; `port` set to its port.
std::string numeric_address(const sockaddr_storage& address, int* port = nullptr);

}  // namespace th::viewer
