#pragma once
// The viewer's API (viewer/server.hpp lists its routes and bounds): one method per route, each
// taking the request and returning the answer's body or throwing HttpError (viewer/http.hpp).
// Private to lib/viewer (it needs <httplib.h>).

#include <httplib.h>

#include <atomic>
#include <functional>
#include <map>
#include <mutex>
#include <string>

#include "bake/bake.hpp"
#include "inference/session.hpp"
#include "viewer/frames.hpp"
#include "viewer/schedule.hpp"
#include "viewer/server.hpp"

namespace th::viewer {

class Api {
 public:
  static constexpr int kMaxSamples = 4096;
  static constexpr int kBakedViews = 4;  // baked views marched at once

  // `stopping`: set when the viewer stops; work in flight ends soon after.
  Api(const inference::Session& session, const Options& options, const std::atomic<bool>& stopping);

  // GET /api/info: people, frames, cameras, sizes and limits (JSON).
  std::string info() const;
  // GET /api/frame: the body's centre and every dataset camera (JSON); data only.
  std::string frame_json(const httplib::Request& req);
  // GET /api/reference: reference view `index` (PNG); data only.
  std::string reference(const httplib::Request& req);
  // GET /api/evaluate: dataset camera C scored as transhuman-eval scores it (JSON).
  std::string evaluate(const httplib::Request& req, const std::function<bool()>& client_gone);
  // GET /api/ground_truth: dataset camera C's target image inside the body's box (PNG).
  std::string ground_truth(const httplib::Request& req);
  // GET /api/bake: the frame's bake, queued when first asked for (JSON).
  std::string bake_json(const httplib::Request& req);

  // A view's image, and how long its stages took as an HTTP Server-Timing header's value
  // (milliseconds: `march` or `render`, then `encode`), so a page or benchmark can tell the
  // server's part of a round trip from the rest.
  struct View {
    std::string bytes;
    std::string timing;
  };
  // GET /api/render: a PNG or JPEG, or HttpError: 409 when a newer request of the same page
  // took over, 503 when the viewer stops, the view runs past its time bound, the renderer stays
  // busy or (baked) too many baked views run.
  View render(const httplib::Request& req, const std::function<bool()>& client_gone);

 private:
  std::pair<int, int> person_frame(const httplib::Request& req) const;
  std::optional<HttpError> stopped_or_gone(const std::function<bool()>& client_gone) const;
  // The view of a frame's bake: no network, so no wait for the renderer.
  View baked_view(int h, int f, const video::PathCamera& camera, int width, int height, int samples,
                  const std::string& mode, const std::string& format,
                  const Interruption& interrupted);

  const inference::Session& session_;
  const Options options_;
  const std::atomic<bool>& stopping_;
  const bake::BakeOptions bake_options_;
  Frames frames_;
  Renderer renderer_;
  Slots baked_views_{kBakedViews};
  std::map<std::string, uint64_t> latest_;  // per client: the newest request seen
  std::mutex latest_mutex_;
  BakeQueue bakes_;  // last: its thread uses the members above
};

}  // namespace th::viewer
