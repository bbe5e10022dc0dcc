#pragma once
// The viewer's frames, kept for the frames last asked for (the least recently used go first), so
// that only a frame's first view pays for them:
//   - data: a frame's reference views and target image size, read without the network (8 kept);
//   - prepared: a frame prepared for rendering (encoder, tokens; Session::prepare), 4 kept.
// Private to lib/viewer.

#include <memory>
#include <mutex>
#include <utility>

#include "inference/session.hpp"
#include "viewer/recent.hpp"

namespace th::viewer {

class Frames {
 public:
  // `view`: the dataset camera whose image size a frame's target takes.
  Frames(const inference::Session& session, int view) : session_(session), view_(view) {}

  // Frame f of person h's data, without the network; any thread.
  std::shared_ptr<const inference::PreparedFrame> data(int h, int f);
  // Frame f of person h prepared; only with the renderer held (it runs the network).
  std::shared_ptr<const inference::PreparedFrame> prepared(int h, int f);

 private:
  using Key = std::pair<int, int>;  // person, frame
  const inference::Session& session_;
  const int view_;
  Recent<Key, std::shared_ptr<const inference::PreparedFrame>> data_{8};  // with data_mutex_
  std::mutex data_mutex_;
  Recent<Key, std::shared_ptr<const inference::PreparedFrame>> prepared_{4};  // with the renderer
};

}  // namespace th::viewer
