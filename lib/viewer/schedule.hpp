#pragma once
// How the viewer's work shares the machine (the bounds viewer/server.hpp documents):
//   - Renderer: the network, for one request or bake at a time, in the order they began to
//     wait; a request gives up with 503 after as long as a render may take.
//   - BakeQueue: one bake in flight, on one thread of its own, and a short queue of the latest
//     frames asked for; a queued bake pushed out by newer ones, or one whose frame is no longer
//     among those kept, is dropped (cancelled between chunks of its network work when running).
//   - Slots: at most a few baked views at once; one more is answered 503 with Retry-After.
// Private to lib/viewer.

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <deque>
#include <functional>
#include <memory>
#include <mutex>
#include <optional>
#include <set>
#include <string>
#include <thread>
#include <utility>

#include "bake/baked_frame.hpp"
#include "viewer/http.hpp"
#include "viewer/recent.hpp"

namespace th::viewer {

using Clock = std::chrono::steady_clock;

// Why a render, a march or a wait for the renderer ends early: nullopt while it may go on.
using Interruption = std::function<std::optional<HttpError>()>;

// 503 naming --render-timeout once `started` is more than `limit_s` seconds ago, for `what`
// ("render", "baked view"); else nullopt.
std::optional<HttpError> past_time_bound(Clock::time_point started, int limit_s,
                                         const std::string& what);

class Renderer {
 public:
  // Held while the network runs; released when it goes.
  class Hold {
   public:
    Hold() = default;
    explicit Hold(Renderer* owner) : owner_(owner) {}
    Hold(Hold&& other) noexcept : owner_(std::exchange(other.owner_, nullptr)) {}
    Hold& operator=(Hold&&) = delete;
    ~Hold();
    explicit operator bool() const { return owner_ != nullptr; }

   private:
    Renderer* owner_ = nullptr;
  };

  // `render_timeout_s`: the longest a render may run, and so (with 5 s more) the longest a
  // request waits for the renderer.
  explicit Renderer(int render_timeout_s) : timeout_s_(render_timeout_s) {}

  // For a request: waits its turn while `interrupted` says nothing; throws what it says, or 503
  // with Retry-After once it has waited longer than a render may take.
  Hold take(const Interruption& interrupted);
  // For a bake: waits its turn while `cancelled` says false; an empty Hold once it says true.
  Hold take_for_bake(const std::function<bool()>& cancelled);

 private:
  // Waits its turn (those that began to wait earlier go first), asking `give_up` every 50 ms:
  // true when held.
  bool wait_turn(const std::function<bool()>& give_up);

  int timeout_s_;
  std::mutex mutex_;
  std::condition_variable turn_;
  bool busy_ = false;
  uint64_t next_ticket_ = 0;
  std::set<uint64_t> waiting_;  // tickets of those waiting, oldest first
};

// A frame's bake as the page sees it.
struct BakeStatus {
  std::string state = "queued";  // queued | baking | ready | failed | cancelled
  double progress = 0, seconds = 0;
  std::string error;                              // failed or cancelled: why
  std::shared_ptr<const bake::BakedFrame> baked;  // ready: the bake
  int queued = 0;                                 // bakes waiting to start, of any frame
  int64_t dropped = 0;  // bakes dropped since the viewer started, of any frame
};

class BakeQueue {
 public:
  static constexpr size_t kKept = 4;    // bakes kept (and frames whose bakes are wanted)
  static constexpr size_t kQueued = 2;  // bakes waiting to start

  // Bakes frame (h, f) calling `progress` between chunks of its work (it throws to cancel the
  // bake); nullopt when `cancelled` said true while it waited for the renderer.
  using Bake = std::function<std::optional<bake::BakedFrame>(
      int h, int f, const std::function<bool()>& cancelled,
      const std::function<void(double)>& progress)>;

  // Starts the thread that bakes; it ends with the queue, or soon after `stopping` is set.
  BakeQueue(Bake bake, const std::atomic<bool>& stopping);
  ~BakeQueue();
  BakeQueue(const BakeQueue&) = delete;
  BakeQueue& operator=(const BakeQueue&) = delete;

  // Frame (h, f)'s bake; asking for a frame neither kept nor queued queues its bake.
  BakeStatus ask(int h, int f);
  // The frame's bake when it is ready, else null.
  std::shared_ptr<const bake::BakedFrame> ready(int h, int f);

 private:
  using Key = std::pair<int, int>;  // person, frame
  struct Entry {
    BakeStatus status;
    bool wanted = true;  // false once dropped: a running bake stops at its next chunk
  };

  void work();
  void run(const Key& key, const std::shared_ptr<Entry>& entry);
  // Drops the queued bakes beyond kQueued (the oldest first) and those no longer kept, and
  // marks the running one unwanted when its frame is no longer kept. With mutex_ held.
  void drop_unwanted();
  bool stopped() const;

  Bake bake_;
  const std::atomic<bool>& stopping_;
  std::mutex mutex_;
  std::condition_variable work_;
  Recent<Key, std::shared_ptr<Entry>> kept_{kKept};
  std::deque<std::pair<Key, std::shared_ptr<Entry>>> queue_;  // waiting, oldest first
  std::shared_ptr<Entry> running_;                            // the bake in flight, or null
  Key running_key_{-1, -1};
  int64_t dropped_ = 0;
  bool closing_ = false;
  std::thread baker_;  // last: started once the rest is ready
};

// At most `count` holders at once.
class Slots {
 public:
  class Hold {
   public:
    explicit Hold(std::atomic<int>* used) : used_(used) {}
    Hold(Hold&& other) noexcept : used_(std::exchange(other.used_, nullptr)) {}
    Hold& operator=(Hold&&) = delete;
    ~Hold() {
      if (used_) --*used_;
    }

   private:
    std::atomic<int>* used_;
  };

  explicit Slots(int count) : count_(count) {}
  // A slot, or nullopt when all are held.
  std::optional<Hold> try_take();

 private:
  const int count_;
  std::atomic<int> used_{0};
};

}  // namespace th::viewer
