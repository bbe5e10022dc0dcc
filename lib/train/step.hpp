#pragma once
// One training step (METHOD 5), in two parts that train() calls in turn:
// - accumulate_step: forward and backward of this process's samples (one per rank it plays),
//   gradients accumulating in the parameters;
// - synchronise_step: across processes, the step's statistics summed, a non-finite loss on any
//   rank turned into an error on all, and the gradients averaged (one process playing several
//   ranks divides them instead).
// The optimiser step, clipping and the schedule stay in train() (trainer.cpp).

#include <torch/types.h>

#include <string>
#include <vector>

#include "core/config.hpp"

namespace th::data {
class Prefetcher;
}
namespace th::dist {
class Communicator;
}
namespace th::metrics {
class LpipsImpl;
}
namespace th::model {
class TransHumanImpl;
}
namespace th::pipeline {
class Tokens;
}

namespace th::train {

// Sums over this process's samples (over all ranks after synchronise_step).
struct StepStats {
  double loss = 0, mse = 0, lpips = 0, psnr = 0, rays = 0;
  std::string bad_loss;  // why this process's sample failed: a non-finite loss, or no body in view
                         // (data parallel)
  bool peer_failed =
      false;  // another rank's sample failed (data parallel): nothing was back-propagated
};

// What a step reads besides the samples.
struct StepContext {
  const Config& config;
  model::TransHumanImpl& model;
  metrics::LpipsImpl* lpips;  // null: no perceptual term
  pipeline::Tokens& tokens;
  const torch::Tensor& canonical;  // v_template (float64: token positions [parity])
  torch::Device device;
};

// Where the run stands, for the message of a non-finite loss.
struct StepPosition {
  int64_t step = 0;
  int epoch = 0;
  int rank = -1;                // -1: a single process
  std::string last_checkpoint;  // "" when none has been written yet
};

// Takes one sample per entry of `ranks` from `loader` (stratified jitter seeded per sample of
// the global batch of `world`), renders its rays and back-propagates its loss. A non-finite loss
// is a th::Error naming the step, the sample and the last good checkpoint, or with `comm` (several
// ranks) only recorded in bad_loss: the ranks agree before each backward pass whether any sample
// failed, and then none back-propagates (synchronise_step turns it into an error everywhere).
StepStats accumulate_step(const StepContext& context, data::Prefetcher& loader,
                          const std::vector<int>& ranks, int world, const StepPosition& where,
                          dist::Communicator* comm);

// With `comm`: one small reduction of the statistics (and of whether a rank saw a non-finite
// loss, then a th::Error everywhere), then the gradients averaged over the `world` samples.
// Without: gradients divided by `per_process` when one process played several ranks.
void synchronise_step(dist::Communicator* comm, StepStats& stats, model::TransHumanImpl& model,
                      int world, int per_process, const StepPosition& where);

}  // namespace th::train
