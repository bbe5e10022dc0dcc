#pragma once
// transhuman-train's loop (SPEC 5): patches of a random target view, MSE + 0.1 LPIPS, Adam with
// element-wise clipping, warm-up + cosine per epoch, atomic checkpoints, exact resume,
// periodic validation renders, NaN and collapse detection, JSON-lines metrics.

#include <torch/types.h>

#include <filesystem>
#include <memory>
#include <optional>
#include <string>

#include "core/config.hpp"
#include "model/transhuman.hpp"

namespace th::dist {
class Communicator;
}

namespace th::train {

struct TrainOptions {
  std::filesystem::path run_dir;  // config.yaml, log.txt, metrics.jsonl, checkpoints/, val/
  bool resume = false;            // continue from run_dir/checkpoints/latest.pt
  int64_t max_steps = -1;         // stop after this global step (tests; -1: the config's length)
  // Data-parallel training: this process's rank (null: a single process). Rank 0 reads the
  // checkpoint and broadcasts its state, and alone writes into run_dir.
  std::shared_ptr<dist::Communicator> comm = nullptr;
  // Samples of this many consecutive ranks per step in this one process (gradient accumulation):
  // 2 without `comm` computes exactly the steps of a 2-rank run.
  int virtual_ranks = 1;
  // Tests: every rank writes its final state to <dir>/rank<r>.pt (empty: not written).
  std::filesystem::path rank_state_dir = {};
};

struct TrainSummary {
  int64_t steps = 0;              // global steps done at the end (including resumed ones)
  int epoch = 0;                  // epoch reached
  double last_loss = 0;
  double last_val_psnr = 0;       // 0 when no validation ran
  std::filesystem::path checkpoint;  // the latest checkpoint written
};

// Trains with `config` on `device`. Throws th::Error for bad input (missing data, NaN loss with
// the step and the last good checkpoint named).
TrainSummary train(const Config& config, const torch::Device& device, const TrainOptions& options);

// Loads the weights of a checkpoint into `model`: ours (.pt, written by train) or the reference
// implementation's (.pth, SPEC 8). Every tensor is checked (model/checked_load.hpp); a checkpoint
// trained with other model.* values is refused naming them, or with `allow_model_mismatch`
// (eval.model_mismatch: warn) loaded with a warning. Throws th::Error naming the file.
void load_weights(model::TransHumanImpl& model, const std::filesystem::path& checkpoint,
                  bool allow_model_mismatch = false);

// Our checkpoint: model weights, optimiser state and the position of the run.
struct CheckpointState {
  int epoch = 0;          // epoch to continue with
  int64_t step = 0;       // global steps done
  int iteration = 0;      // iterations done within `epoch`
};

}  // namespace th::train
