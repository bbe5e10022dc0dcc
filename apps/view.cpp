// transhuman-view: an interactive novel-view viewer (lib/viewer/server.hpp says what it serves).
// Loads the model and the data once and serves a page (127.0.0.1 by default) where the camera is
// dragged with the mouse and the person re-renders from there.
#include <poll.h>
#include <spdlog/spdlog.h>
#include <unistd.h>

#include <array>
#include <atomic>
#include <chrono>
#include <csignal>
#include <cstdio>
#include <iostream>
#include <thread>

#include "app/app.hpp"
#include "bake/bake.hpp"
#include "core/error.hpp"
#include "inference/session.hpp"
#include "viewer/server.hpp"

namespace {

// SIGINT, SIGTERM and SIGHUP: a handler (whichever thread receives them) writes the signal's
// number to a pipe; one thread reads it. Before the server listens that ends the process (the
// viewer writes nothing); afterwards it stops the server (the render in flight is cancelled,
// connections close) and main returns 0. Should that take more than a second and a half, or a
// second signal come, the process ends at once.
std::atomic<th::viewer::Server*> g_server{nullptr};
int g_signal_pipe[2] = {-1, -1};

extern "C" void on_stop_signal(int sig) {
  const char byte = char(sig);
  [[maybe_unused]] const ssize_t n = ::write(g_signal_pipe[1], &byte, 1);
}

void stop_on_signals() {
  if (::pipe(g_signal_pipe) != 0) return;
  std::thread([] {
    char sig = 0;
    while (::read(g_signal_pipe[0], &sig, 1) != 1) {
    }
    th::viewer::Server* server = g_server.load();
    if (!server) std::_Exit(128 + sig);
    const auto start = std::chrono::steady_clock::now();
    spdlog::info("viewer: signal {}, stopping", int(sig));
    server->stop();
    pollfd again{g_signal_pipe[0], POLLIN, 0};
    if (::poll(&again, 1, 1500) > 0 || g_server.load()) {
      const auto ms = std::chrono::duration_cast<std::chrono::milliseconds>(
                          std::chrono::steady_clock::now() - start)
                          .count();
      spdlog::warn("viewer: still stopping {} ms after the signal; ending now", ms);
      std::fflush(nullptr);
      std::_Exit(0);
    }
  }).detach();
  struct sigaction action {};
  action.sa_handler = on_stop_signal;
  sigemptyset(&action.sa_mask);
  for (const int sig : {SIGINT, SIGTERM, SIGHUP}) sigaction(sig, &action, nullptr);
}

}  // namespace

int main(int argc, char** argv) {
  stop_on_signals();
  return th::app::guarded_main("transhuman-view", [&]() -> int {
    CLI::App cli{
        "Interactive novel-view viewer: serves a page where the camera is dragged with the mouse\n"
        "and the person re-renders from there (open the printed URL in a browser)."};
    th::app::CommonOptions options;
    th::app::ModelOptions model;
    th::viewer::Options o;
    std::string human;
    th::app::add_common_options(cli, options);
    th::app::add_model_options(cli, model);
    th::app::add_precision_option(cli, options);
    cli.add_option("--human", human,
                   "the person shown first (folder name); default: the setting's first");
    cli.add_option(
           "--frame", o.start_frame,
           "the body frame shown first (annots index); default: the person's first test frame")
        ->check(th::app::at_least(0));
    cli.add_option(
        "--host", o.host,
        "address to listen on (default 127.0.0.1: this machine only; '' or 0.0.0.0: every IPv4 "
        "interface, '::': every interface)");
    cli.add_option("--port", o.port, "port (refused when another program listens on it)")
        ->check(th::app::in_range(1, 65535));
    cli.add_option(
           "--allow-host", o.allow_hosts,
           "a name the browser may reach the viewer by, beside 127.0.0.1, localhost, [::1] and the "
           "--host address (requests naming another Host are refused); repeatable")
        ->allow_extra_args(false);
    cli.add_option("--render-timeout", o.render_timeout_s,
                   "longest one render may run, seconds (then 503)")
        ->check(th::app::in_range(1, 3600));
    cli.add_option("--view", o.view, "camera whose image size the first view takes (METHOD 7: 3)")
        ->check(th::app::at_least(0));
    cli.add_option("--max-size", o.max_size, "largest image side a request may ask for")
        ->check(th::app::in_range(16, 4096));
    bool no_bake = false;
    cli.add_flag("--no-bake", no_bake,
                 "do not bake frames: views while moving come from the network (small, slow)");
    cli.add_option("--bake-voxel", o.bake_voxel, "bake: grid spacing in metres")
        ->check(th::app::in_range(0.001, 0.2));
    if (const auto rc = th::app::parse_command_line(cli, argc, argv)) return *rc;
    for (const auto& name : o.allow_hosts) th::viewer::allowed_host(name);
    o.bake = !no_bake;
    th::app::apply_model_options(model, options);

    const auto ctx = th::app::start_run(options, "transhuman-view");
    const th::inference::Session session(ctx.config, ctx.device, model.checkpoint);
    if (o.view >= session.human(0).num_cameras())
      th::fail("--view ", o.view, ": ", session.human(0).name(), " has ",
               session.human(0).num_cameras(), " cameras");
    o.start_human = session.find_human(human);
    const auto& first = session.human(o.start_human);
    if (o.start_frame >= first.num_frames())
      th::fail("--frame ", o.start_frame, ": ", first.name(), " has ", first.num_frames(),
               " frames");
    if (o.bake) {
      // A grid finer than memory allows is refused now, not when the first bake runs out of it:
      // the largest box among each person's frame shown first.
      th::bake::BakeOptions bake;
      bake.voxel = o.bake_voxel;
      std::array<double, 6> largest{};
      std::string which;
      double volume = -1;
      for (int h = 0; h < int(session.dataset().humans().size()); ++h) {
        const auto listed = session.setting_frames(h);
        const int frame = h == o.start_human && o.start_frame >= 0 ? o.start_frame
                          : listed.empty()                         ? 0
                                                                   : listed.front();
        const auto box =
            th::bake::bake_box(session.dataset().load_body(session.human(h), frame).bounds);
        const double v = (box[3] - box[0]) * (box[4] - box[1]) * (box[5] - box[2]);
        if (v <= volume) continue;
        volume = v;
        largest = box;
        which = session.human(h).name() + " frame " + std::to_string(frame);
      }
      th::bake::check_bake_memory(largest, bake, session, which);
    }
    if (options.dry_run) return 0;

    th::viewer::Server server(session, o);
    g_server = &server;
    std::cout << "transhuman-view: open " << server.url() << " in a browser (Ctrl-C stops)\n"
              << "transhuman-view: listening on " << server.interfaces() << "; answering to "
              << server.host_names() << std::endl;
    server.run();
    g_server = nullptr;
    return 0;
  });
}
