#pragma once
// transhuman-train's loop (METHOD 5): patches of a random target view, MSE + 0.1 LPIPS (loss.hpp),
// Adam with element-wise clipping, warm-up + cosine per epoch (schedule.hpp), atomic checkpoints
// and exact resume (pipeline/checkpoint.hpp), periodic validation renders, NaN and collapse
// detection, JSON-lines metrics; data-parallel across processes (step.hpp, lib/dist).

#include <torch/types.h>

#include <filesystem>
#include <memory>
#include <optional>
#include <string>

#include "core/config.hpp"

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
  // Fine-tuning: start from this checkpoint's weights and token groups (ours .pt or the
  // reference's .pth), with a fresh optimiser and schedule. Empty: model.* initialisation.
  std::filesystem::path init_from = {};
};

struct TrainSummary {
  int64_t steps = 0;  // global steps done at the end (including resumed ones)
  int epoch = 0;      // epoch reached
  double last_loss = 0;
  double last_val_psnr = 0;          // 0 when no validation ran
  std::filesystem::path checkpoint;  // the latest checkpoint written
};

// Checks a fine-tuning start (--init) before a run is written: its weights are read into the
// model of `config` as train() reads them (every tensor, name and shape checked). th::Error naming
// the file; a checkpoint of ours named .pth (read as the reference's) is said to be one.
void check_init(const Config& config, const std::filesystem::path& checkpoint);

// Trains with `config` on `device`. Throws th::Error for bad input (missing data, NaN loss with
// the step and the last good checkpoint named).
TrainSummary train(const Config& config, const torch::Device& device, const TrainOptions& options);

}  // namespace th::train
