#include "viewer/schedule.hpp"

#include <spdlog/spdlog.h>

namespace th::viewer {

std::optional<HttpError> past_time_bound(Clock::time_point started, int limit_s,
                                         const std::string& what) {
  if (Clock::now() - started <= std::chrono::seconds(limit_s)) return std::nullopt;
  return HttpError{503,
                   "the " + what + " ran past the viewer's bound of " + std::to_string(limit_s) +
                       " s per render (--render-timeout) and was stopped: ask for fewer samples "
                       "or a smaller image"};
}

Renderer::Hold::~Hold() {
  if (!owner_) return;
  {
    std::lock_guard<std::mutex> lock(owner_->mutex_);
    owner_->busy_ = false;
  }
  owner_->turn_.notify_all();
}

bool Renderer::wait_turn(const std::function<bool()>& give_up) {
  std::unique_lock<std::mutex> lock(mutex_);
  const uint64_t ticket = next_ticket_++;
  waiting_.insert(ticket);
  const auto my_turn = [&] { return !busy_ && *waiting_.begin() == ticket; };
  for (;;) {
    if (turn_.wait_for(lock, std::chrono::milliseconds(50), my_turn)) {
      waiting_.erase(ticket);
      busy_ = true;
      return true;
    }
    // Asked without the lock: it may look at a socket.
    lock.unlock();
    const bool quit = give_up();
    lock.lock();
    if (quit) {
      waiting_.erase(ticket);
      lock.unlock();
      turn_.notify_all();  // the next in line may be free to go now
      return false;
    }
  }
}

Renderer::Hold Renderer::take(const Interruption& interrupted) {
  if (auto e = interrupted()) throw *e;
  const auto until = Clock::now() + std::chrono::seconds(timeout_s_ + 5);
  std::optional<HttpError> why;
  const bool held = wait_turn([&] {
    why = interrupted();
    if (!why && Clock::now() > until)
      why = HttpError{503,
                      "busy: the renderer has been taken by others for " +
                          std::to_string(timeout_s_ + 5) + " s",
                      2};
    return bool(why);
  });
  if (!held) throw *why;
  Hold hold(this);
  if (auto e = interrupted()) throw *e;
  return hold;
}

Renderer::Hold Renderer::take_for_bake(const std::function<bool()>& cancelled) {
  if (cancelled() || !wait_turn(cancelled)) return Hold();
  return Hold(this);
}

BakeQueue::BakeQueue(Bake bake, const std::atomic<bool>& stopping)
    : bake_(std::move(bake)), stopping_(stopping), baker_([this] { work(); }) {}

BakeQueue::~BakeQueue() {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    closing_ = true;
  }
  work_.notify_all();
  baker_.join();
}

bool BakeQueue::stopped() const { return closing_ || stopping_.load(); }

BakeStatus BakeQueue::ask(int h, int f) {
  std::lock_guard<std::mutex> lock(mutex_);
  const Key key{h, f};
  auto* found = kept_.find(key);
  std::shared_ptr<Entry> entry = found ? *found : nullptr;
  // A frame asked for again after its bake was dropped is queued anew.
  if (!entry || entry->status.state == "cancelled") {
    entry = std::make_shared<Entry>();
    kept_.put(key, entry);
    queue_.emplace_back(key, entry);
    drop_unwanted();
    work_.notify_one();
  }
  BakeStatus status = entry->status;
  status.queued = int(queue_.size());
  status.dropped = dropped_;
  return status;
}

std::shared_ptr<const bake::BakedFrame> BakeQueue::ready(int h, int f) {
  std::lock_guard<std::mutex> lock(mutex_);
  const auto* found = kept_.find({h, f});
  return found && (*found)->status.state == "ready" ? (*found)->status.baked : nullptr;
}

void BakeQueue::drop_unwanted() {
  const auto kept = [&](const Key& key, const std::shared_ptr<Entry>& entry) {
    const auto* k = kept_.peek(key);
    return k && *k == entry;
  };
  const auto drop = [&](Entry& entry) {
    entry.wanted = false;
    entry.status.state = "cancelled";
    entry.status.error = "dropped: newer frames were asked for";
    ++dropped_;
  };
  for (auto it = queue_.begin(); it != queue_.end();) {
    if (kept(it->first, it->second)) {
      ++it;
    } else {
      drop(*it->second);
      it = queue_.erase(it);
    }
  }
  for (; queue_.size() > kQueued; queue_.pop_front()) drop(*queue_.front().second);
  if (running_ && running_->wanted && !kept(running_key_, running_)) {
    running_->wanted = false;
    ++dropped_;
  }
}

void BakeQueue::work() {
  std::unique_lock<std::mutex> lock(mutex_);
  for (;;) {
    // In slices: `stopping` is set without a notification.
    work_.wait_for(lock, std::chrono::milliseconds(100),
                   [&] { return stopped() || !queue_.empty(); });
    if (stopped()) break;
    if (queue_.empty()) continue;
    auto [key, entry] = queue_.front();
    queue_.pop_front();
    running_ = entry;
    running_key_ = key;
    entry->status.state = "baking";
    lock.unlock();
    run(key, entry);
    lock.lock();
    running_.reset();
  }
  for (auto& queued : queue_) {
    queued.second->status.state = "failed";
    queued.second->status.error = "the viewer is stopping";
  }
  queue_.clear();
}

void BakeQueue::run(const Key& key, const std::shared_ptr<Entry>& entry) {
  struct Cancelled {};
  const auto started = Clock::now();
  const auto cancelled = [&] {
    std::lock_guard<std::mutex> lock(mutex_);
    return stopped() || !entry->wanted;
  };
  const auto progress = [&](double p) {
    std::lock_guard<std::mutex> lock(mutex_);
    if (stopped() || !entry->wanted) throw Cancelled{};
    entry->status.progress = p;
  };
  const auto seconds = [&] {
    return std::chrono::duration<double>(Clock::now() - started).count();
  };
  std::string outcome = "failed", error;
  std::shared_ptr<const bake::BakedFrame> baked;
  try {
    if (auto result = bake_(key.first, key.second, cancelled, progress)) {
      spdlog::info("viewer: baked {} frame {} in {:.1f} s ({} bricks, {:.1f} MiB)", result->human,
                   result->frame, seconds(), result->stored_bricks(),
                   double(result->bytes()) / 1048576.0);
      baked = std::make_shared<const bake::BakedFrame>(std::move(*result));
      outcome = "ready";
    } else {
      outcome = "cancelled";
    }
  } catch (const Cancelled&) {
    outcome = "cancelled";
  } catch (const std::exception& e) {
    spdlog::error("viewer: the bake of person {} frame {} failed: {}", key.first, key.second,
                  e.what());
    error = e.what();
  }
  std::lock_guard<std::mutex> lock(mutex_);
  if (outcome == "cancelled") {
    if (stopped()) {
      outcome = "failed";
      error = "the viewer is stopping";
    } else {
      error = "dropped: newer frames were asked for";
      spdlog::info(
          "viewer: the bake of person {} frame {} was dropped after {:.1f} s: newer "
          "frames were asked for",
          key.first, key.second, seconds());
    }
  }
  entry->status.state = outcome;
  entry->status.error = error;
  entry->status.baked = std::move(baked);
  entry->status.seconds = seconds();
}

std::optional<Slots::Hold> Slots::try_take() {
  if (used_.fetch_add(1) >= count_) {
    --used_;
    return std::nullopt;
  }
  return Hold(&used_);
}

}  // namespace th::viewer
