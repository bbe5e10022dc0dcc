#include "viewer/frames.hpp"

namespace th::viewer {

std::shared_ptr<const inference::PreparedFrame> Frames::data(int h, int f) {
  const Key key{h, f};
  {
    std::lock_guard<std::mutex> lock(data_mutex_);
    if (const auto* found = data_.find(key)) return *found;
  }
  auto frame = std::make_shared<inference::PreparedFrame>();
  frame->human = h;
  frame->frame = f;
  frame->sample = session_.dataset().load_item({h, f, view_}, 0);
  std::lock_guard<std::mutex> lock(data_mutex_);
  return data_.put(key, std::move(frame));
}

std::shared_ptr<const inference::PreparedFrame> Frames::prepared(int h, int f) {
  const Key key{h, f};
  if (const auto* found = prepared_.find(key)) return *found;
  return prepared_.put(
      key, std::make_shared<const inference::PreparedFrame>(session_.prepare(h, f, view_)));
}

}  // namespace th::viewer
