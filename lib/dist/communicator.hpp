#pragma once
// Data parallelism over PyTorch's own distributed engine, c10d, as LibTorch ships it: rendezvous
// through a c10d::TCPStore hosted by rank 0, collectives through c10d::ProcessGroupGloo on CPU
// or c10d::ProcessGroupNCCL on CUDA (only when the linked LibTorch was built with NCCL).
//
// Every collective is bounded by the timeout: a rank that dies or hangs makes the others throw
// th::Error (naming the operation and the timeout) instead of waiting forever.

#include <torch/types.h>

#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <torch/csrc/distributed/c10d/Store.hpp>
#include <vector>

#include "core/torch_compat.hpp"

namespace th::dist {

// Where this process sits among the ranks: the usual launcher environment (torchrun, SLURM
// wrappers, transhuman-train --nproc).
struct Environment {
  int rank = 0;
  int world_size = 1;
  int local_rank = 0;
  int local_world_size = 1;  // ranks on this machine
  std::string master_addr = "127.0.0.1";
  int master_port = 29500;
};

// Reads RANK, WORLD_SIZE, LOCAL_RANK (default: RANK), LOCAL_WORLD_SIZE (default 1), MASTER_ADDR
// (default 127.0.0.1) and MASTER_PORT (default 29500); numbers in decimal. nullopt when WORLD_SIZE
// is not set. Throws th::Error naming the variable when a value is malformed or out of range.
std::optional<Environment> environment_from_env();

// Which c10d backend a run uses: "gloo" or "nccl" for `requested` (auto | gloo | nccl) on `device`.
// Throws th::Error when NCCL is asked for but this LibTorch has no NCCL, or the device is the CPU.
std::string resolve_backend(const std::string& requested, const torch::Device& device);
// Whether the linked LibTorch has the NCCL process group.
bool nccl_available();

class Communicator {
 public:
  // Joins the others: rank 0 hosts the store at master_addr:master_port, every rank connects to
  // it and builds the process group. Throws th::Error when the others do not arrive within
  // `timeout_s`. bucket_mb: gradient all-reduce bucket size.
  Communicator(const Environment& env, const std::string& backend, const torch::Device& device,
               double timeout_s, double bucket_mb);
  ~Communicator();
  Communicator(const Communicator&) = delete;
  Communicator& operator=(const Communicator&) = delete;

  int rank() const { return rank_; }
  int world_size() const { return world_size_; }
  const std::string& backend() const { return backend_; }
  double timeout_s() const { return timeout_s_; }

  // Rank 0's `bytes` on every rank (the others' input is ignored).
  void broadcast(std::string& bytes, const std::string& what);

  // Sums the parameters' gradients over the ranks and divides them by `divisor` (the global
  // batch), in flattened buckets of at most bucket_mb. A gradient that is undefined on every
  // rank stays undefined; one defined on some rank only is treated as zero elsewhere.
  void average_gradients(const std::vector<torch::Tensor>& params, double divisor);

  // The element-wise mean over the ranks of floating tensors, in place (BatchNorm running
  // statistics, so every rank holds the same buffers).
  void average(const std::vector<torch::Tensor>& tensors, const std::string& what);

  // The element-wise sum over the ranks of a tensor, in place (synchronised BatchNorm's
  // statistics).
  void sum_in_place(torch::Tensor& tensor, const std::string& what);

  // The element-wise sum over the ranks of a few numbers (loss statistics, flags).
  std::vector<double> sum(const std::vector<double>& values, const std::string& what);

  void barrier(const std::string& what);

  // Runs `fn` on rank 0 only (checkpoints, validation) while the others wait for it. Rank 0
  // sends a heartbeat meanwhile, so `fn` may take longer than the timeout; the others give up
  // with an error when rank 0 dies, stops beating for the timeout, or `fn` throws there.
  void on_lead(const std::function<void()>& fn, const std::string& what);

  // Work split over the ranks: `assignment[r]` lists rank r's items. Every rank calls `work` on
  // its own items in that order; rank 0 receives every result and calls `collect(item, bytes)`
  // for each (its own at once, the others' as they arrive), then `finish` (which writes the
  // outputs). A rank whose `work` throws sends its error, and every rank exits naming it; a rank
  // that dies or sends nothing for the timeout is named by rank 0, whose failure reaches the
  // others (on_lead). Results travel through the rendezvous store, one item at a time.
  void sharded(const std::vector<std::vector<int64_t>>& assignment,
               const std::function<std::string(int64_t)>& work,
               const std::function<void(int64_t, const std::string&)>& collect,
               const std::function<void()>& finish, const std::string& what);

  // Records this rank's failure in the store, where rank 0 waiting in `sharded` finds it and
  // stops at once, naming it, instead of waiting out the timeout; the first message stays. The
  // destructor announces one when it runs during an exception (an error anywhere after joining).
  void announce(const std::string& message);

  // Seconds spent in the gradient all-reduce (flatten, reduce, unflatten), in all and in the last
  // call.
  double allreduce_seconds_total() const { return allreduce_total_; }
  double allreduce_seconds_last() const { return allreduce_last_; }

 private:
  template <class F>
  auto guarded(const std::string& what, F&& f) -> decltype(f());
  torch::Tensor to_comm(const torch::Tensor& t) const;  // where the backend wants the tensor

  int rank_, world_size_;
  std::string backend_;
  torch::Device device_;
  double timeout_s_;
  int64_t bucket_bytes_;
  c10::intrusive_ptr<c10d::Store> store_;
  c10::intrusive_ptr<compat::CollectiveGroup> group_;  // Gloo or NCCL
  bool failed_ = false;      // after a failed collective the group is left alone (not torn down)
  int64_t lead_calls_ = 0;   // on_lead sequence number (store keys)
  int64_t shard_calls_ = 0;  // sharded sequence number (store keys)
  double allreduce_total_ = 0, allreduce_last_ = 0;
};

}  // namespace th::dist
