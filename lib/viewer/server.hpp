#pragma once
// The interactive viewer's HTTP server: a page (viewer/page.hpp) where the camera is dragged
// with the mouse and the person re-renders from there, and the API it calls. Every parameter is
// validated; a bad one is a 400 naming it.
//   GET /                 the page        GET /three/<file>   libjs-three's two scripts
//   GET /api/info         people, their frames and cameras, sizes and limits (JSON)
//   GET /api/frame?human=H&frame=F
//                         the body's centre and every dataset camera as eye/forward/up/fovy (JSON)
//   GET /api/render?human=H&frame=F&eye=x,y,z&forward=x,y,z&up=x,y,z&fovy=DEG&width=W&height=H
//                   [&samples=S][&mode=rgb|depth|acc][&seq=N][&client=ID]  a PNG; camera=C
//                         instead of eye..height renders dataset camera C exactly
//   GET /api/bake?human=H&frame=F   queues the frame's bake (METHOD 7.1) and says how far it
//                         is: {"state": baking|ready|failed, "waiting" (not started yet),
//                         "progress", "queued" (bakes waiting), "dropped" (so far), ...}
//   GET /api/render?...&baked=1   the view from the frame's bake (404 until it is ready): no
//                         network, milliseconds; format=jpeg for a JPEG instead of a PNG.
//                         Every view answers with Server-Timing: march or render, then encode (ms)
//   GET /api/reference?human=H&frame=F&index=I                    reference view I (PNG)
//   GET /api/evaluate?human=H&frame=F&camera=C   dataset camera C scored as transhuman-eval
//                         scores it: {"psnr", "ssim"} (JSON)
//   GET /api/ground_truth?human=H&frame=F&camera=C                its ground truth (PNG)
// One render runs at a time; a request with a higher seq from the same page (client=ID) cancels
// that page's request in flight (409 for the cancelled one), so a dragged camera never waits
// behind stale frames. Prepared frames and bakes are kept (the least recently used go first), so
// only a frame's first view pays for them.
// A render is bounded: image side (max_size), samples (4096) and time (render_timeout_s, then
// 503 naming the bound); it is cancelled between bands of rows when its client goes away or the
// server stops. Requests and bakes take the renderer in the order they began to wait; a request
// that has waited longer than a render may take gets 503 with Retry-After. /api/info,
// /api/frame, /api/reference and /api/ground_truth read data only and answer while a render runs.
// Bakes (viewer/schedule.hpp): one at a time, on one thread, holding the renderer while it runs;
// at most 2 wait, the latest frames asked for. A waiting bake pushed out by a newer one, or a
// bake (running or waiting) whose frame is no longer among the 4 kept, is dropped (a running one
// between chunks of its network work), and queued again when its frame is asked for again.
// A baked view needs no renderer and never waits for one; it has the bounds of a render (size,
// samples, render_timeout_s, cancelled between bands of rows as a render is), and at most 4 run
// at once: one more gets 503 with Retry-After.
// As a server (viewer/access.hpp, viewer/listener.hpp): the Host header must name this server
// (421 otherwise), the API answers its own page only (403 for cross-origin requests), request
// bodies are refused unread (413), the port is exclusive, and slow or idle connections hold a
// thread for a few seconds at most.

#include <memory>
#include <string>
#include <vector>

#include "inference/session.hpp"

namespace th::viewer {

struct Options {
  std::string host = "127.0.0.1";  // another address is announced with a warning; "" or "::": all
  int port = 7007;
  std::vector<std::string>
      allow_hosts;            // Host names answered beside loopback and the bound address
  int render_timeout_s = 60;  // longest one render may run
  int view = 3;               // the dataset camera the first view starts from
  int max_size = 512;         // largest image side a request may ask for
  int start_human = 0;        // shown first
  int start_frame = -1;       // -1: the person's first test frame
  bool bake = true;           // bake each frame shown, for views in milliseconds while moving
  double bake_voxel = 0.02;   // the bake's grid spacing, metres
};

// `name` as the Host header carries it (lower case, IPv6 in brackets); throws th::Error unless
// it is a host name or address without a port (--allow-host).
std::string allowed_host(const std::string& name);

class Server {
 public:
  // Binds host:port exclusively (th::Error naming the address and why when it cannot, e.g. a
  // port in use) and registers the routes; serves nothing yet.
  Server(const inference::Session& session, const Options& options);
  ~Server();
  Server(const Server&) = delete;
  Server& operator=(const Server&) = delete;

  // A URL a browser on this machine opens: loopback for an any-address bind, IPv6 in brackets.
  std::string url() const;
  // Where it listens, in words ("127.0.0.1 only", "every interface (IPv4 and IPv6)").
  std::string interfaces() const;
  // The Host names it answers to, with the port.
  std::string host_names() const;
  // Serves until stop().
  void run();
  // Ends run() within a fraction of a second: cancels the render in flight and closes every
  // connection. Callable from any thread, also before run().
  void stop();

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace th::viewer
