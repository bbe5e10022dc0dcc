#include "dist/communicator.hpp"

#include <spdlog/spdlog.h>

#include <torch/csrc/distributed/c10d/PrefixStore.hpp>
#include <torch/csrc/distributed/c10d/ProcessGroupGloo.hpp>
#include <torch/csrc/distributed/c10d/TCPStore.hpp>
#ifdef USE_C10D_NCCL
#include <torch/csrc/distributed/c10d/ProcessGroupNCCL.hpp>
#endif
#include <torch/torch.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <condition_variable>
#include <csignal>
#include <cstdlib>
#include <cstring>
#include <exception>
#include <future>
#include <mutex>
#include <thread>

#include "core/config_io.hpp"
#include "core/error.hpp"

namespace th::dist {
namespace {

using Clock = std::chrono::steady_clock;

int env_int(const char* name, const char* value, int lo, int hi) {
  const auto v = config::decimal_integer(value);
  if (!v || *v < lo || *v > hi)
    fail("environment variable ", name, "='", value, "' must be an integer in [", lo, ", ", hi,
         "]");
  return int(*v);
}

std::string message_of(const std::exception& e) {
  if (const auto* c = dynamic_cast<const c10::Error*>(&e)) return c->what_without_backtrace();
  return e.what();
}

bool is_loopback(const std::string& host) {
  return host == "localhost" || host.rfind("127.", 0) == 0 || host == "::1";
}

std::vector<uint8_t> bytes_of(const std::string& s) { return {s.begin(), s.end()}; }

// The store key under which rank r announces its failure.
std::string failure_key(int r) { return "failed/" + std::to_string(r); }

}  // namespace

std::optional<Environment> environment_from_env() {
  const char* world = std::getenv("WORLD_SIZE");
  if (!world) return std::nullopt;
  Environment e;
  e.world_size = env_int("WORLD_SIZE", world, 1, 1 << 20);
  const char* rank = std::getenv("RANK");
  if (!rank) fail("WORLD_SIZE is set (", world, ") but RANK is not");
  e.rank = env_int("RANK", rank, 0, e.world_size - 1);
  const char* local = std::getenv("LOCAL_RANK");
  e.local_rank = local ? env_int("LOCAL_RANK", local, 0, 1 << 20) : e.rank;
  if (const char* ranks_here = std::getenv("LOCAL_WORLD_SIZE"))
    e.local_world_size = env_int("LOCAL_WORLD_SIZE", ranks_here, 1, e.world_size);
  if (const char* addr = std::getenv("MASTER_ADDR")) {
    if (!*addr) fail("environment variable MASTER_ADDR is empty");
    e.master_addr = addr;
  }
  if (const char* port = std::getenv("MASTER_PORT"))
    e.master_port = env_int("MASTER_PORT", port, 1, 65535);
  return e;
}

bool nccl_available() {
#ifdef USE_C10D_NCCL
  return true;
#else
  return false;
#endif
}

std::string resolve_backend(const std::string& requested, const torch::Device& device) {
  if (requested == "gloo") return "gloo";
  if (requested == "nccl") {
    if (!nccl_available())
      fail("train.dist_backend=nccl but this LibTorch was built without NCCL (use gloo or auto)");
    if (!device.is_cuda())
      fail("train.dist_backend=nccl needs device cuda (the device is ", device.str(), ")");
    return "nccl";
  }
  if (requested != "auto")
    fail("train.dist_backend='", requested, "' is not one of auto, gloo, nccl");
  return nccl_available() && device.is_cuda() ? "nccl" : "gloo";
}

template <class F>
auto Communicator::guarded(const std::string& what, F&& f) -> decltype(f()) {
  try {
    return f();
  } catch (const Error&) {
    failed_ = true;
    throw;
  } catch (const std::exception& e) {
    failed_ = true;
    // A rank that failed and said why (announce) is named with its own error.
    for (int r = 0; r < world_size_; ++r) {
      if (r == rank_) continue;
      try {
        if (!store_ || !store_->check({failure_key(r)})) continue;
        const auto v = store_->get(failure_key(r));
        fail("rank ", r, " of ", world_size_, " failed during ", what, ": ",
             std::string(v.begin(), v.end()));
      } catch (const Error&) {
        throw;
      } catch (const std::exception&) {
        break;  // the store is gone too: say what is known
      }
    }
    fail("rank ", rank_, " of ", world_size_, ": ", what, " failed: ", message_of(e),
         " (another rank has probably died or hung; ranks wait train.dist_timeout_s = ", timeout_s_,
         " s for each other)");
  }
}

Communicator::Communicator(const Environment& env, const std::string& backend,
                           const torch::Device& device, double timeout_s, double bucket_mb)
    : rank_(env.rank),
      world_size_(env.world_size),
      backend_(backend),
      device_(device),
      timeout_s_(timeout_s),
      bucket_bytes_(std::max<int64_t>(1, int64_t(bucket_mb * 1048576.0))) {
  TORCH_CHECK(world_size_ >= 1 && rank_ >= 0 && rank_ < world_size_, "Communicator: rank ", rank_,
              " of ", world_size_);
  TORCH_CHECK(backend_ == "gloo" || backend_ == "nccl", "Communicator: backend ", backend_);
  const auto timeout = std::chrono::milliseconds(int64_t(timeout_s * 1000));
  // A peer that died must surface as an error of the collective, not as SIGPIPE killing this
  // process (Python, where c10d usually runs, ignores SIGPIPE too).
  std::signal(SIGPIPE, SIG_IGN);
  c10d::TCPStoreOptions so;
  so.port = uint16_t(env.master_port);
  so.isServer = rank_ == 0;
  so.numWorkers = size_t(world_size_);
  so.waitWorkers = true;
  so.timeout = timeout;
  compat::use_classic_tcpstore(so, 0);
  const std::string where = "rank " + std::to_string(rank_) + " of " + std::to_string(world_size_) +
                            ": rendezvous at " + env.master_addr + ":" +
                            std::to_string(env.master_port);
  // The store's own timeout does not bound every wait (a port held by another program that
  // accepts the connection and never answers keeps the client waiting), so the rendezvous runs
  // on a thread of its own, given up after the timeout (the process then exits with the error).
  using Store = c10::intrusive_ptr<c10d::TCPStore>;
  auto joined = std::make_shared<std::promise<Store>>();
  auto store = joined->get_future();
  std::thread([joined, addr = env.master_addr, so] {
    try {
      joined->set_value(c10::make_intrusive<c10d::TCPStore>(addr, so));
    } catch (...) {
      joined->set_exception(std::current_exception());
    }
  }).detach();
  if (store.wait_for(std::chrono::duration<double>(timeout_s + 2)) != std::future_status::ready) {
    failed_ = true;
    fail(where, " got no answer within ", timeout_s, " s",
         rank_ == 0 ? " (did every rank start?)"
                    : " (is MASTER_PORT rank 0's? another program there accepts connections but "
                      "does not answer)");
  }
  try {
    store_ = store.get();
  } catch (const std::exception& e) {
    failed_ = true;
    fail(where, " failed within ", timeout_s, " s: ", message_of(e),
         rank_ == 0 ? " (is the port free? did every rank start?)"
                    : " (is rank 0 running, and are MASTER_ADDR/MASTER_PORT its address?)");
  }
  // Each rank joins once: a second process with the same RANK at this address (another run
  // given the same MASTER_PORT, or a launcher that repeats a RANK) is refused before it can
  // touch the process group of the run it found.
  guarded("joining the run", [&] {
    if (store_->add("joined/" + std::to_string(rank_), 1) > 1)
      fail("rank ", rank_, " of the run at ", env.master_addr, ":", env.master_port,
           " has joined already: another run uses this MASTER_PORT, or RANK=", rank_,
           " was given to two processes (give each run its own port)");
  });
  auto group_store = c10::make_intrusive<c10d::PrefixStore>("pg", store_);
  guarded("creating the " + backend_ + " process group", [&] {
    if (backend_ == "gloo") {
      auto options = c10d::ProcessGroupGloo::Options::create(timeout);
      // GLOO_SOCKET_IFNAME picks the network interface as in PyTorch; a loopback master means
      // one machine; otherwise the address this machine's hostname resolves to.
      if (const char* ifname = std::getenv("GLOO_SOCKET_IFNAME"); ifname && *ifname)
        options->devices.push_back(c10d::ProcessGroupGloo::createDeviceForInterface(ifname));
      else if (is_loopback(env.master_addr))
        options->devices.push_back(c10d::ProcessGroupGloo::createDeviceForHostname("127.0.0.1"));
      else
        options->devices.push_back(c10d::ProcessGroupGloo::createDefaultDevice());
      group_ =
          c10::make_intrusive<c10d::ProcessGroupGloo>(group_store, rank_, world_size_, options);
    } else {
#ifdef USE_C10D_NCCL
      auto options = c10d::ProcessGroupNCCL::Options::create();
      options->timeout = timeout;
      group_ =
          c10::make_intrusive<c10d::ProcessGroupNCCL>(group_store, rank_, world_size_, options);
#else
      fail("this LibTorch has no NCCL process group");
#endif
    }
  });
  barrier("joining the process group");
  spdlog::info("distributed: rank {} of {} joined ({} via {}:{}, timeout {} s)", rank_, world_size_,
               backend_, env.master_addr, env.master_port, timeout_s_);
}

Communicator::~Communicator() {
  if (std::uncaught_exceptions() > 0) {  // (a constructor that threw runs no destructor)
    try {
      announce("rank " + std::to_string(rank_) +
               " stopped with an error (its own message is on its stderr)");
    } catch (...) {
      // the store is gone (rank 0 has exited): nobody is left to tell
    }
  }
  if (failed_) {
    // A collective failed: the group may still wait on a dead peer, and tearing it down could
    // block. The process is about to exit with the error; leave the objects to the OS.
    (void)group_.release();
    (void)store_.release();
  }
}

torch::Tensor Communicator::to_comm(const torch::Tensor& t) const {
  return backend_ == "nccl" ? t.to(device_) : t.to(torch::kCPU);
}

void Communicator::broadcast(std::string& bytes, const std::string& what) {
  guarded("broadcasting " + what, [&] {
    std::vector<torch::Tensor> size{to_comm(torch::tensor({int64_t(bytes.size())}, torch::kInt64))};
    group_->broadcast(size)->wait();
    const int64_t n = size[0].cpu().item<int64_t>();
    auto data = torch::empty({n}, torch::kUInt8);
    if (rank_ == 0) std::memcpy(data.data_ptr(), bytes.data(), size_t(n));
    std::vector<torch::Tensor> payload{to_comm(data)};
    group_->broadcast(payload)->wait();
    if (rank_ != 0) {
      const auto cpu = payload[0].cpu().contiguous();
      bytes.assign(reinterpret_cast<const char*>(cpu.data_ptr()), size_t(n));
    }
  });
}

void Communicator::average_gradients(const std::vector<torch::Tensor>& params, double divisor) {
  const auto t0 = Clock::now();
  guarded("the gradient all-reduce", [&] {
    // Which gradients exist on any rank (a parameter unused by every rank keeps none).
    std::vector<double> defined(params.size());
    for (size_t i = 0; i < params.size(); ++i) defined[i] = params[i].grad().defined();
    std::vector<torch::Tensor> mask{to_comm(torch::tensor(defined, torch::kFloat64))};
    group_->allreduce(mask)->wait();
    const auto any = mask[0].cpu().contiguous();
    const double* anywhere = any.data_ptr<double>();

    // Buckets of consecutive gradients of one dtype, flattened: one collective per bucket. All
    // buckets are launched before the first is waited for, so flattening overlaps the transfer.
    struct Bucket {
      std::vector<torch::Tensor> grads;
      std::vector<torch::Tensor> flat;
      c10::intrusive_ptr<c10d::Work> work;
    };
    std::vector<Bucket> buckets;
    int64_t bytes = 0;
    for (size_t i = 0; i < params.size(); ++i) {
      if (anywhere[i] == 0) continue;
      const auto& p = params[i];
      if (!p.grad().defined()) p.mutable_grad() = torch::zeros_like(p);
      const auto& g = p.grad();
      const int64_t nb = g.numel() * int64_t(g.element_size());
      if (buckets.empty() || bytes + nb > bucket_bytes_ ||
          buckets.back().grads.front().scalar_type() != g.scalar_type()) {
        buckets.emplace_back();
        bytes = 0;
      }
      buckets.back().grads.push_back(g);
      bytes += nb;
    }
    for (auto& b : buckets) {
      std::vector<torch::Tensor> views;
      for (const auto& g : b.grads) views.push_back(g.reshape({-1}));
      b.flat = {to_comm(torch::cat(views))};
      b.work = group_->allreduce(b.flat);
    }
    for (auto& b : buckets) {
      b.work->wait();
      auto flat = b.flat[0].to(b.grads.front().device());
      flat.div_(divisor);
      int64_t offset = 0;
      for (auto& g : b.grads) {
        g.copy_(flat.slice(0, offset, offset + g.numel()).view_as(g));
        offset += g.numel();
      }
    }
  });
  allreduce_last_ = std::chrono::duration<double>(Clock::now() - t0).count();
  allreduce_total_ += allreduce_last_;
}

void Communicator::average(const std::vector<torch::Tensor>& tensors, const std::string& what) {
  std::vector<torch::Tensor> floating;
  for (const auto& t : tensors)
    if (t.defined() && t.is_floating_point()) floating.push_back(t);
  if (floating.empty()) return;
  guarded("averaging " + what, [&] {
    std::vector<torch::Tensor> views;
    for (const auto& t : floating) views.push_back(t.reshape({-1}).to(torch::kFloat64));
    std::vector<torch::Tensor> flat{to_comm(torch::cat(views))};
    group_->allreduce(flat)->wait();
    const auto mean = flat[0].div(world_size_);
    int64_t offset = 0;
    torch::NoGradGuard no_grad;
    for (auto& t : floating) {
      t.copy_(mean.slice(0, offset, offset + t.numel()).view_as(t));
      offset += t.numel();
    }
  });
}

void Communicator::announce(const std::string& message) {
  if (!store_->check({failure_key(rank_)})) store_->set(failure_key(rank_), bytes_of(message));
}

void Communicator::sum_in_place(torch::Tensor& tensor, const std::string& what) {
  guarded(what, [&] {
    std::vector<torch::Tensor> t{to_comm(tensor.contiguous())};
    group_->allreduce(t)->wait();
    torch::NoGradGuard no_grad;
    tensor.copy_(t[0]);
  });
}

std::vector<double> Communicator::sum(const std::vector<double>& values, const std::string& what) {
  return guarded(what, [&] {
    std::vector<torch::Tensor> t{to_comm(torch::tensor(values, torch::kFloat64))};
    group_->allreduce(t)->wait();
    const auto cpu = t[0].cpu().contiguous();
    return std::vector<double>(cpu.data_ptr<double>(), cpu.data_ptr<double>() + cpu.numel());
  });
}

void Communicator::barrier(const std::string& what) {
  guarded(what, [&] { group_->barrier()->wait(); });
}

void Communicator::on_lead(const std::function<void()>& fn, const std::string& what) {
  const std::string key = "lead/" + std::to_string(lead_calls_++);
  const auto timeout = std::chrono::duration<double>(timeout_s_);
  if (rank_ == 0) {
    // Heartbeat: a few beats per timeout, so a long checkpoint or validation is not taken for a
    // hang.
    std::mutex m;
    std::condition_variable cv;
    bool stop = false;
    const auto interval = std::chrono::duration<double>(std::clamp(timeout_s_ / 8, 0.05, 5.0));
    std::thread beat([&] {
      std::unique_lock<std::mutex> lock(m);
      while (!stop) {
        try {
          store_->add(key + "/beat", 1);
        } catch (const std::exception&) {
          return;  // the others are gone; fn's result decides
        }
        cv.wait_for(lock, interval, [&] { return stop; });
      }
    });
    auto finish = [&](const std::string& status) {
      {
        std::lock_guard<std::mutex> lock(m);
        stop = true;
      }
      cv.notify_all();
      beat.join();
      store_->set(key + "/done", bytes_of(status));
    };
    try {
      fn();
    } catch (const std::exception& e) {
      try {
        finish("error: " + message_of(e));
      } catch (const std::exception&) {
      }
      throw;
    }
    guarded(what, [&] { finish("ok"); });
    return;
  }
  guarded(what, [&] {
    int64_t beats = -1;
    auto since = Clock::now();
    for (;;) {
      if (store_->check({key + "/done"})) {
        const auto v = store_->get(key + "/done");
        const std::string status(v.begin(), v.end());
        if (status != "ok") fail("rank 0 failed during ", what, ": ", status.substr(7));
        return;
      }
      const int64_t now_beats = store_->add(key + "/beat", 0);
      if (now_beats != beats) {
        beats = now_beats;
        since = Clock::now();
      } else if (Clock::now() - since > timeout) {
        fail("rank ", rank_, " of ", world_size_, ": rank 0 gave no sign of life for ", timeout_s_,
             " s during ", what, " (train.dist_timeout_s)");
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
    }
  });
}

void Communicator::sharded(const std::vector<std::vector<int64_t>>& assignment,
                           const std::function<std::string(int64_t)>& work,
                           const std::function<void(int64_t, const std::string&)>& collect,
                           const std::function<void()>& finish, const std::string& what) {
  TORCH_CHECK(int(assignment.size()) == world_size_, "sharded: ", assignment.size(),
              " assignments for ", world_size_, " ranks");
  const std::string tag = "shard/" + std::to_string(shard_calls_++) + "/";
  auto result_key = [&](int r, size_t j) {
    return tag + std::to_string(r) + "/" + std::to_string(j);
  };
  const auto& mine = assignment[size_t(rank_)];
  const auto timeout = std::chrono::duration<double>(timeout_s_);

  if (rank_ == 0) {
    on_lead(
        [&] {
          std::vector<size_t> received(size_t(world_size_), 0);
          // One more result of rank r: true when one was collected; with `wait`, waits for it
          // (up to the timeout).
          auto receive = [&](int r, bool wait) {
            const auto& items = assignment[size_t(r)];
            if (received[size_t(r)] >= items.size()) return false;
            const std::string key = result_key(r, received[size_t(r)]);
            const auto since = Clock::now();
            for (;;) {
              if (store_->check({key})) {
                const auto v = store_->get(key);
                store_->deleteKey(key);
                collect(items[received[size_t(r)]++], std::string(v.begin(), v.end()));
                return true;
              }
              if (store_->check({failure_key(r)})) {
                const auto v = store_->get(failure_key(r));
                fail("rank ", r, " of ", world_size_, " failed during ", what, ": ",
                     std::string(v.begin(), v.end()));
              }
              if (!wait) return false;
              if (Clock::now() - since > timeout)
                fail("rank ", r, " of ", world_size_, " sent no result of ", what, " for ",
                     timeout_s_, " s: it died or hung (train.dist_timeout_s)");
              std::this_thread::sleep_for(std::chrono::milliseconds(20));
            }
          };
          for (const int64_t item : mine) {
            collect(item, work(item));
            for (int r = 1; r < world_size_; ++r)
              while (receive(r, false)) {
              }
          }
          for (int r = 1; r < world_size_; ++r)
            while (receive(r, true)) {
            }
          finish();
        },
        what);
    barrier("the end of " + what);  // the others have read the outcome before rank 0 exits
    return;
  }

  // The on_lead call rank 0 makes for this work: its status tells whether rank 0 gave up.
  const std::string lead_done = "lead/" + std::to_string(lead_calls_) + "/done";
  try {
    for (size_t j = 0; j < mine.size(); ++j) {
      const std::string bytes = work(mine[j]);
      guarded("sending a result of " + what, [&] {
        if (store_->check({lead_done})) {
          const auto v = store_->get(lead_done);
          const std::string status(v.begin(), v.end());
          if (status != "ok") fail("rank 0 failed during ", what, ": ", status.substr(7));
        }
        store_->set(result_key(rank_, j), bytes_of(bytes));
      });
    }
  } catch (const std::exception& e) {
    try {
      announce(message_of(e));
    } catch (const std::exception&) {
      // rank 0 is gone: this rank's own error is what is reported
    }
    throw;
  }
  on_lead([] {}, what);
  barrier("the end of " + what);
}

}  // namespace th::dist
