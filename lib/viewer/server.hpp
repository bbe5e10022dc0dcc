#pragma once
// The interactive viewer's HTTP server: a page (viewer/page.hpp) where the camera is dragged
// with the mouse and the person re-renders from there, and the API it calls. Every parameter is
// validated; a bad one is a 400 naming it.
//   GET /                 the page        GET /three/<file>   libjs-three's two scripts
//   GET /api/info         people, their frames and cameras, sizes and limits (JSON)
//   GET /api/frame?human=H&frame=F
//                         the body's centre and every dataset camera as eye/forward/up/fovy (JSON)
//   GET /api/render?human=H&frame=F&eye=x,y,z&forward=x,y,z&up=x,y,z&fovy=DEG&width=W&height=H
//                   [&samples=S][&mode=rgb|depth|acc][&seq=N][&client=ID]  a PNG; camera=C instead of
//                         eye..height renders dataset camera C exactly
//   GET /api/reference?human=H&frame=F&index=I                    reference view I (PNG)
//   GET /api/evaluate?human=H&frame=F&camera=C   dataset camera C scored as transhuman-eval
//                         scores it: {"psnr", "ssim"} (JSON)
//   GET /api/ground_truth?human=H&frame=F&camera=C                its ground truth (PNG)
// One render runs at a time; a request with a higher seq from the same page (client=ID) cancels
// that page's request in flight (409 for the cancelled one), so a dragged camera never waits
// behind stale frames. Prepared frames are kept, so only a frame's first view pays for them.

#include <memory>
#include <string>

#include "inference/session.hpp"

namespace th::viewer {

struct Options {
  std::string host = "127.0.0.1";  // another address is announced with a warning
  int port = 7007;
  int view = 3;          // the dataset camera the first view starts from
  int max_size = 512;    // largest image side a request may ask for
  int start_human = 0;   // shown first
  int start_frame = -1;  // -1: the person's first test frame
};

class Server {
 public:
  // Binds host:port (th::Error when it cannot) and registers the routes; serves nothing yet.
  Server(const inference::Session& session, const Options& options);
  ~Server();
  Server(const Server&) = delete;
  Server& operator=(const Server&) = delete;

  std::string url() const;
  // Serves until stop().
  void run();
  // Ends run(); callable from any thread.
  void stop();

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace th::viewer
