#include "viewer/server.hpp"

#include <arpa/inet.h>
#include <httplib.h>
#include <netinet/in.h>
#include <spdlog/spdlog.h>

#include <atomic>
#include <filesystem>
#include <fstream>
#include <functional>
#include <sstream>

#include "core/error.hpp"
#include "report/report.hpp"
#include "viewer/access.hpp"
#include "viewer/api.hpp"
#include "viewer/listener.hpp"
#include "viewer/page.hpp"

namespace th::viewer {
namespace fs = std::filesystem;

namespace {

std::string read_file(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

}  // namespace

struct Server::Impl {
  Impl(const inference::Session& session, const Options& o)
      : options(o), api(session, o, stopping) {}
  ~Impl() { stopping = true; }  // the bake in flight ends before the API goes
  Options options;
  std::atomic<bool> stopping{false};
  Api api;
  Listener server;
  std::unique_ptr<Access> access;  // once bound
};

Server::Server(const inference::Session& session, const Options& options)
    : impl_(std::make_unique<Impl>(session, options)) {
  Listener& server = impl_->server;
  Api& api = impl_->api;
  const fs::path three = th::report::find_three_js();
  const auto answer = [](httplib::Response& res, int status, const std::string& message) {
    res.status = status;
    res.set_header("Cache-Control", "no-store");
    res.set_content(message.empty() || message.back() != '\n' ? message + "\n" : message,
                    "text/plain; charset=utf-8");
  };
  const auto guarded =
      [answer](const std::function<void(const httplib::Request&, httplib::Response&)>& fn) {
        return [fn, answer](const httplib::Request& req, httplib::Response& res) {
          try {
            fn(req, res);
          } catch (const HttpError& e) {
            answer(res, e.status, e.message);
            if (e.retry_after_s > 0) res.set_header("Retry-After", std::to_string(e.retry_after_s));
          } catch (const th::Error& e) {
            answer(res, 400, e.what());
          } catch (const std::exception& e) {
            spdlog::error("viewer: {}", e.what());
            answer(res, 500, std::string("internal error: ") + e.what());
          }
        };
      };
  // Who is answered at all (viewer/access.hpp), before any route and before a body is read.
  server.set_pre_routing_handler(
      [this, answer](const httplib::Request& req, httplib::Response& res) {
        const auto refusal = impl_->access->check(req);
        if (!refusal) return httplib::Server::HandlerResponse::Unhandled;
        Listener::close_after_response();
        answer(res, refusal->status, refusal->message);
        if (refusal->status == 405) res.set_header("Allow", "GET, HEAD");
        return httplib::Server::HandlerResponse::Handled;
      });
  // "Expect: 100-continue" is answered before routing: refused uploads are refused there too.
  server.set_expect_100_continue_handler(
      [this, answer](const httplib::Request& req, httplib::Response& res) {
        const auto refusal = impl_->access->check(req);
        if (!refusal) return 100;
        Listener::close_after_response();
        answer(res, refusal->status, refusal->message);
        return refusal->status;
      });
  server.Get("/", guarded([](const httplib::Request&, httplib::Response& res) {
               res.set_header("X-Frame-Options", "DENY");
               res.set_header("Content-Security-Policy", "frame-ancestors 'none'");
               res.set_content(kPage, "text/html; charset=utf-8");
             }));
  for (const char* name : {"three.min.js", "OrbitControls.js"}) {
    const std::string file = name;
    server.Get("/three/" + file,
               guarded([three, file](const httplib::Request&, httplib::Response& res) {
                 const fs::path path = file == "three.min.js"
                                           ? three / "build" / file
                                           : three / "examples" / "js" / "controls" / file;
                 if (three.empty() || !fs::is_regular_file(path)) {
                   res.status = 404;
                   res.set_content("three.js not found (Debian: apt-get install libjs-three)\n",
                                   "text/plain");
                   return;
                 }
                 res.set_content(read_file(path), "application/javascript");
               }));
  }
  server.Get("/api/info", guarded([&api](const httplib::Request&, httplib::Response& res) {
               res.set_content(api.info(), "application/json");
             }));
  server.Get("/api/frame", guarded([&api](const httplib::Request& req, httplib::Response& res) {
               res.set_content(api.frame_json(req), "application/json");
             }));
  server.Get("/api/reference", guarded([&api](const httplib::Request& req, httplib::Response& res) {
               res.set_content(api.reference(req), "image/png");
             }));
  server.Get("/api/evaluate", guarded([&api](const httplib::Request& req, httplib::Response& res) {
               res.set_content(api.evaluate(req, Listener::client_gone), "application/json");
             }));
  server.Get("/api/ground_truth",
             guarded([&api](const httplib::Request& req, httplib::Response& res) {
               res.set_content(api.ground_truth(req), "image/png");
             }));
  server.Get("/api/bake", guarded([&api](const httplib::Request& req, httplib::Response& res) {
               res.set_header("Cache-Control", "no-store");
               res.set_content(api.bake_json(req), "application/json");
             }));
  server.Get("/api/render", guarded([&api](const httplib::Request& req, httplib::Response& res) {
               const auto view = api.render(req, Listener::client_gone);
               res.set_header("Cache-Control", "no-store");
               res.set_header("Server-Timing", view.timing);
               const bool jpeg = req.has_param("format") && req.get_param_value("format") == "jpeg";
               res.set_content(view.bytes, jpeg ? "image/jpeg" : "image/png");
             }));

  // An empty --host means every interface, as it does for most servers (getaddrinfo would
  // take it for loopback).
  server.bind(options.host.empty() ? "0.0.0.0" : options.host, options.port);
  impl_->access = std::make_unique<Access>(options.host, server.bound_address(), options.port,
                                           options.allow_hosts);
  if (interfaces().find("only") == std::string::npos)
    spdlog::warn("LISTENING ON {}: anyone who can reach it can use the viewer", interfaces());
}

Server::~Server() = default;

namespace {

bool is_loopback(const sockaddr_storage& a) {
  if (a.ss_family == AF_INET)
    return (ntohl(reinterpret_cast<const sockaddr_in&>(a).sin_addr.s_addr) >> 24) == 127;
  return a.ss_family == AF_INET6 &&
         IN6_IS_ADDR_LOOPBACK(&reinterpret_cast<const sockaddr_in6&>(a).sin6_addr);
}

bool is_any(const sockaddr_storage& a) {
  if (a.ss_family == AF_INET)
    return reinterpret_cast<const sockaddr_in&>(a).sin_addr.s_addr == htonl(INADDR_ANY);
  return a.ss_family == AF_INET6 &&
         IN6_IS_ADDR_UNSPECIFIED(&reinterpret_cast<const sockaddr_in6&>(a).sin6_addr);
}

}  // namespace

std::string Server::url() const {
  const auto bound = impl_->server.bound_address();
  const std::string& host = impl_->options.host;
  in6_addr scratch{};
  const bool literal = host.empty() || ::inet_pton(AF_INET, host.c_str(), &scratch) == 1 ||
                       ::inet_pton(AF_INET6, host.c_str(), &scratch) == 1;
  std::string name;
  if (is_any(bound))
    name = impl_->server.ipv6_only() ? "[::1]" : "127.0.0.1";
  else if (literal)
    name = url_host(numeric_address(bound));
  else
    name = host;
  return "http://" + name + ":" + std::to_string(impl_->options.port) + "/";
}

std::string Server::interfaces() const {
  const auto bound = impl_->server.bound_address();
  const std::string address = url_host(numeric_address(bound));
  if (is_any(bound)) {
    const char* families = bound.ss_family == AF_INET  ? ", IPv4)"
                           : impl_->server.ipv6_only() ? ", IPv6)"
                                                       : ", IPv4 and IPv6)";
    return "every interface of this machine (" + address + families;
  }
  return address + (is_loopback(bound) ? " only (this machine)" : " (reachable from the network)");
}

std::string Server::host_names() const { return impl_->access->names(); }

void Server::run() {
  if (!impl_->stopping) impl_->server.listen_after_bind();
}

void Server::stop() {
  impl_->stopping = true;
  impl_->server.shut_down();
}

}  // namespace th::viewer
