#include "viewer/access.hpp"

#include <arpa/inet.h>
#include <ifaddrs.h>
#include <netinet/in.h>

#include <algorithm>
#include <cctype>
#include <cstring>

#include "core/error.hpp"
#include "viewer/listener.hpp"
#include "viewer/server.hpp"

namespace th::viewer {
namespace {

std::string lower(std::string text) {
  std::transform(text.begin(), text.end(), text.begin(),
                 [](unsigned char c) { return char(std::tolower(c)); });
  return text;
}

bool is_ipv6(const std::string& text) {
  in6_addr address{};
  return ::inet_pton(AF_INET6, text.c_str(), &address) == 1;
}

bool is_any_address(const sockaddr_storage& a) {
  if (a.ss_family == AF_INET)
    return reinterpret_cast<const sockaddr_in&>(a).sin_addr.s_addr == htonl(INADDR_ANY);
  if (a.ss_family == AF_INET6)
    return IN6_IS_ADDR_UNSPECIFIED(&reinterpret_cast<const sockaddr_in6&>(a).sin6_addr);
  return false;
}

// This machine's interface addresses of `family` (AF_INET, or AF_UNSPEC: both), as a Host header
// names them; link-local IPv6 addresses are left out (a browser does not name them in Host).
std::vector<std::string> interface_addresses(int family) {
  std::vector<std::string> out;
  ifaddrs* list = nullptr;
  if (::getifaddrs(&list) != 0) return out;
  for (const ifaddrs* i = list; i; i = i->ifa_next) {
    if (!i->ifa_addr || (i->ifa_addr->sa_family != AF_INET && i->ifa_addr->sa_family != AF_INET6))
      continue;
    if (family == AF_INET && i->ifa_addr->sa_family != AF_INET) continue;
    sockaddr_storage a{};
    std::memcpy(&a, i->ifa_addr,
                i->ifa_addr->sa_family == AF_INET6 ? sizeof(sockaddr_in6) : sizeof(sockaddr_in));
    if (a.ss_family == AF_INET6 &&
        IN6_IS_ADDR_LINKLOCAL(&reinterpret_cast<const sockaddr_in6&>(a).sin6_addr))
      continue;
    const std::string name = numeric_address(a);
    if (!name.empty()) out.push_back(url_host(name));
  }
  ::freeifaddrs(list);
  return out;
}

bool is_host_name(const std::string& name) {
  return !name.empty() && name.size() <= 253 &&
         std::all_of(name.begin(), name.end(), [](unsigned char c) {
           return std::isalnum(c) || c == '-' || c == '.' || c == '_';
         });
}

}  // namespace

std::string url_host(const std::string& name) {
  return is_ipv6(name) ? "[" + lower(name) + "]" : lower(name);
}

Access::Access(const std::string& host, const sockaddr_storage& bound, int port,
               const std::vector<std::string>& allowed)
    : port_(port), names_{"127.0.0.1", "localhost", "[::1]"} {
  const auto add = [this](const std::string& name) {
    if (!name.empty() && std::find(names_.begin(), names_.end(), name) == names_.end())
      names_.push_back(name);
  };
  if (is_any_address(bound)) {
    // An IPv6 any-address socket serves IPv4 too (unless IPv6-only: then those names never come).
    for (const auto& name : interface_addresses(bound.ss_family == AF_INET ? AF_INET : AF_UNSPEC))
      add(name);
  } else {
    add(url_host(host));
    add(url_host(numeric_address(bound)));
  }
  for (const auto& name : allowed) add(allowed_host(name));
}

std::string allowed_host(const std::string& name) {
  const std::string bare = name.size() > 2 && name.front() == '[' && name.back() == ']'
                               ? name.substr(1, name.size() - 2)
                               : name;
  if (is_ipv6(bare)) return url_host(bare);
  if (bare.find(':') != std::string::npos)
    fail("--allow-host '", name, "': give the name without a port (the viewer's port is implied)");
  if (!is_host_name(bare)) fail("--allow-host '", name, "' is not a host name or address");
  return lower(bare);
}

std::string Access::names() const {
  std::string out;
  for (const auto& name : names_)
    out += (out.empty() ? "" : ", ") + name + ":" + std::to_string(port_);
  return out;
}

std::optional<Refusal> Access::check_host(const std::string& host) const {
  const auto refuse = [&](const std::string& why) {
    return Refusal{421, "refused: Host '" + host + "' " + why + "; this viewer answers to " +
                            names() +
                            " (start it with --allow-host NAME to answer to another name)\n"};
  };
  std::string name = host, port;
  if (!host.empty() && host.front() == '[') {
    const size_t close = host.find(']');
    if (close == std::string::npos) return refuse("is not a host name");
    name = host.substr(0, close + 1);
    if (close + 1 < host.size()) {
      if (host[close + 1] != ':') return refuse("is not a host name");
      port = host.substr(close + 2);
    }
  } else if (const size_t colon = host.find(':'); colon != std::string::npos) {
    name = host.substr(0, colon);
    port = host.substr(colon + 1);
  }
  name = lower(name);
  if (std::find(names_.begin(), names_.end(), name) == names_.end())
    return refuse("is not a name of this viewer");
  const bool port_ok = port.empty() ? port_ == 80 : port == std::to_string(port_);
  if (!port_ok) return refuse("does not name this viewer's port");
  return std::nullopt;
}

std::optional<Refusal> Access::check(const httplib::Request& req) const {
  if (!req.has_header("Host"))
    return Refusal{400,
                   "refused: the request has no Host header (the viewer answers HTTP/1.1 requests "
                   "that name it)\n"};
  const std::string host = req.get_header_value("Host");
  if (auto refusal = check_host(host)) return refusal;
  const bool chunked = req.has_header("Transfer-Encoding");
  const std::string length = req.get_header_value("Content-Length");
  if (chunked || (!length.empty() && length != "0")) {
    return Refusal{
        413, "refused: a request body (" + (chunked ? std::string("chunked") : length + " bytes") +
                 "); the viewer's requests are queries without a body, nothing was read\n"};
  }
  if (req.method != "GET" && req.method != "HEAD") {
    return Refusal{405,
                   "refused: method " + req.method + "; the viewer answers GET requests only\n"};
  }
  if (req.path.rfind("/api/", 0) != 0)
    return std::nullopt;  // the page and three.js: any site may link them
  const std::string own = "http://" + lower(host);
  if (req.has_header("Origin") && lower(req.get_header_value("Origin")) != own)
    return Refusal{403, "refused: a request from origin '" + req.get_header_value("Origin") +
                            "'; the viewer's API answers its own page only (" + own + ")\n"};
  const std::string site = req.get_header_value("Sec-Fetch-Site");
  if (!site.empty() && site != "same-origin" && site != "none")
    return Refusal{
        403, "refused: a " + site +
                 " request (Sec-Fetch-Site); the viewer's API answers its own page only (" + own +
                 ")\n"};
  return std::nullopt;
}

}  // namespace th::viewer
