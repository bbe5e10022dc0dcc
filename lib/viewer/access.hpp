#pragma once
// Which requests the viewer answers at all, before any route runs. A page elsewhere on the web
// can make a browser send requests to a server on the user's machine: through a name that it
// resolves to 127.0.0.1 (DNS rebinding; the page then is "same-origin" with that name), or as a
// cross-site request. So:
//   - the Host header must name this server: 127.0.0.1, localhost or [::1], the address it is
//     bound to (for an any-address bind, this machine's interface addresses), or a name the user
//     allowed (--allow-host), with the server's port; otherwise 421;
//   - an API request must come from the viewer's own page: an Origin header, when sent, is the
//     server's own origin, and Sec-Fetch-Site, when sent, is same-origin or none (typed by the
//     user); otherwise 403;
//   - only GET and HEAD, without a body (405, 413): the API takes queries, so an upload is refused
//     before it is read.
// A refused request's connection is closed after the answer (its body, if any, is never read).
// Private to lib/viewer (it needs <httplib.h>).

#include <httplib.h>
#include <sys/socket.h>

#include <optional>
#include <string>
#include <vector>

namespace th::viewer {

struct Refusal {
  int status = 0;
  std::string message;
};

class Access {
 public:
  // `host` as given to --host, `bound` the address it bound to, `allowed` the --allow-host
  // names (checked by allowed_host, viewer/server.hpp).
  Access(const std::string& host, const sockaddr_storage& bound, int port,
         const std::vector<std::string>& allowed);

  // Why `req` is refused, or nullopt when it is answered.
  std::optional<Refusal> check(const httplib::Request& req) const;

  // The names the Host header may carry, with the port ("127.0.0.1:7007, localhost:7007, ...").
  std::string names() const;

 private:
  std::optional<Refusal> check_host(const std::string& host) const;

  int port_;
  std::vector<std::string> names_;  // lower case, IPv6 addresses in brackets
};

// `name` as a URL writes it: an IPv6 address in brackets.
std::string url_host(const std::string& name);

}  // namespace th::viewer
