#include "train/trainer.hpp"

#include <spdlog/spdlog.h>
#include <torch/torch.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <functional>
#include <nlohmann/json.hpp>
#include <numeric>
#include <optional>
#include <sstream>

#include "body/smpl.hpp"
#include "core/error.hpp"
#include "core/progress.hpp"
#include "data/dataset.hpp"
#include "data/sampler.hpp"
#include "dist/communicator.hpp"
#include "io/files.hpp"
#include "metrics/lpips.hpp"
#include "model/encoder.hpp"
#include "pipeline/checked_load.hpp"
#include "pipeline/checkpoint.hpp"
#include "pipeline/jsonl.hpp"
#include "pipeline/pipeline.hpp"
#include "train/plot.hpp"
#include "train/schedule.hpp"
#include "train/step.hpp"
#include "train/validation.hpp"

namespace th::train {
namespace fs = std::filesystem;
using pipeline::CheckpointState;

namespace {

// A resumed run continues from its checkpoint's step: rows a killed run logged after that
// step are dropped from metrics.jsonl (the file is rewritten whole), so no step appears twice.
// So is a line that is not JSON: one cut short when the run was killed.
void drop_rows_after(const fs::path& file, int64_t step) {
  std::error_code ec;
  if (!fs::exists(file, ec)) return;
  std::istringstream in(io::read_file(file));
  std::string kept, line;
  int64_t dropped = 0;
  while (std::getline(in, line)) {
    if (line.empty()) continue;
    const auto row = nlohmann::json::parse(line, nullptr, /*allow_exceptions=*/false);
    const bool later = row.is_object() && row.contains("step") && row["step"].is_number() &&
                       row["step"].get<double>() > double(step);
    if (row.is_discarded() || later) {
      ++dropped;
      continue;
    }
    kept += line + "\n";
  }
  if (dropped == 0) return;
  io::write_file_atomic(file, kept);
  spdlog::info("resume: dropped {} row(s) of {} logged after step {}, the checkpoint's", dropped,
               file.filename().string(), step);
}

// Data parallelism: every rank starts from rank 0's state (fresh or resumed), sent as the bytes of
// a checkpoint, so no rank needs the run directory.
CheckpointState broadcast_state(dist::Communicator& comm, model::TransHumanImpl& model,
                                torch::optim::Adam& optim, const CheckpointState& st) {
  std::string bytes;
  if (comm.rank() == 0) bytes = pipeline::checkpoint_bytes(model, optim, st);
  comm.broadcast(bytes, "rank 0's weights and optimiser state");
  if (comm.rank() == 0) return st;
  return pipeline::restore_checkpoint_bytes(bytes, model, optim, "rank 0's weights");
}

// BatchNorm running statistics: averaged over the ranks after each step so every rank holds the
// same buffers (the batch statistics used in training are per sample, METHOD 3.1).
std::vector<torch::Tensor> batchnorm_statistics(torch::nn::Module& net) {
  std::vector<torch::Tensor> out;
  for (const auto& m : net.modules(/*include_self=*/false))
    if (auto* bn = dynamic_cast<model::BatchNormImpl*>(m.get())) {
      out.push_back(bn->running_mean);
      out.push_back(bn->running_var);
    }
  return out;
}

void set_lr(torch::optim::Adam& optim, double lr) {
  for (auto& group : optim.param_groups())
    static_cast<torch::optim::AdamOptions&>(group.options()).lr(lr);
}

// Running means of the logged quantities between two metrics lines.
struct LogWindow {
  double loss = 0, psnr = 0, seconds = 0, allreduce = 0;
  int64_t rays = 0, steps = 0;
};

// One call of train(): the run's state, and the loop split into its parts (the step itself is
// in step.cpp, the loss in loss.cpp).
class Run {
 public:
  Run(const Config& config, const torch::Device& device, const TrainOptions& options);
  TrainSummary go();

 private:
  void on_lead(const std::function<void()>& fn, const std::string& what) {
    if (comm_)
      comm_->on_lead(fn, what);
    else
      fn();
  }
  StepPosition position(int epoch) const {
    return {st_.step, epoch, comm_ ? proc_ : -1,
            last_ckpt_.empty() ? std::string() : last_ckpt_.string()};
  }
  void record_step(const StepStats& stats, double seconds, double lr, int epoch,
                   const data::Prefetcher& loader);
  void log_step(const StepStats& stats, double lr, int epoch, const data::Prefetcher& loader);
  bool out_of_time();
  void end_of_epoch(int epoch);
  void checkpoint(bool keep_epoch_copy);
  void finish(int epoch);

  const Config& config_;
  const TrainConfig& tc_;
  torch::Device device_;
  const TrainOptions& options_;
  dist::Communicator* comm_;
  // Data parallelism: `world_` samples per step, one per (virtual) rank; this process computes
  // the samples of `ranks_` and rank 0 alone writes into the run directory.
  int procs_, proc_, per_process_, world_;
  bool lead_;
  std::vector<int> ranks_;
  fs::path run_, ckpt_dir_, val_dir_;

  std::shared_ptr<const data::Dataset> train_set_, val_set_;
  torch::Tensor canonical_;  // float64 v_template: token positions [parity]
  model::TransHuman model_{nullptr};
  std::unique_ptr<torch::optim::Adam> optim_;
  std::shared_ptr<metrics::LpipsImpl> lpips_;
  std::unique_ptr<pipeline::Tokens> tokens_;
  std::vector<torch::Tensor> bn_stats_;

  CheckpointState st_;
  fs::path last_ckpt_;
  int64_t stop_step_ = 0;
  std::optional<pipeline::JsonlWriter> metrics_log_;
  std::optional<Progress> progress_;
  std::chrono::steady_clock::time_point started_;
  LogWindow window_;
  TrainSummary summary_;
};

Run::Run(const Config& config, const torch::Device& device, const TrainOptions& options)
    : config_(config),
      tc_(config.train),
      device_(device),
      options_(options),
      comm_(options.comm.get()) {
  TORCH_CHECK(options.virtual_ranks >= 1, "train: virtual_ranks must be >= 1");
  procs_ = comm_ ? comm_->world_size() : 1;
  proc_ = comm_ ? comm_->rank() : 0;
  per_process_ = options.virtual_ranks;
  world_ = procs_ * per_process_;
  lead_ = proc_ == 0;
  ranks_.resize(static_cast<size_t>(per_process_));
  std::iota(ranks_.begin(), ranks_.end(), proc_ * per_process_);

  run_ = options.run_dir;
  ckpt_dir_ = run_ / "checkpoints";
  val_dir_ = run_ / "val";
  if (lead_) {
    fs::create_directories(ckpt_dir_);
    fs::create_directories(val_dir_);
  }

  const auto smpl = data::load_body_model(config.data);
  train_set_ = std::make_shared<const data::Dataset>(config.data, config.data.train_setting,
                                                     data::Dataset::Mode::Train, smpl);
  if (train_set_->size() == 0)
    fail("training setting '", config.data.train_setting, "' has no samples");
  if (tc_.val_views > 0 && lead_)
    val_set_ = std::make_shared<const data::Dataset>(config.data, config.data.test_setting,
                                                     data::Dataset::Mode::Test, smpl);
  if (val_set_) val_set_->require_targets();

  torch::manual_seed(uint64_t(config.seed));
  model_ = model::TransHuman(config.model);
  // The constructor loads model.encoder.pretrained (and logs either way).
  model_->to(device);
  model_->set_products(model::select_products(config.precision, config.fp32_products, device));
  optim_ = std::make_unique<torch::optim::Adam>(
      model_->parameters(),
      torch::optim::AdamOptions(tc_.lr).betas({tc_.beta1, tc_.beta2}).eps(tc_.eps));
  if (tc_.lpips_weight > 0)
    lpips_ = metrics::try_load_lpips(tc_.lpips_weights, device, "the perceptual loss");

  canonical_ = smpl->v_template;
  if (options.resume && lead_) {
    last_ckpt_ = ckpt_dir_ / "latest.pt";
    st_ = pipeline::load_checkpoint(last_ckpt_, *model_, *optim_);
    spdlog::info("resumed from {} at epoch {}, step {}", last_ckpt_.string(), st_.epoch, st_.step);
  } else if (!options.init_from.empty() && lead_) {
    pipeline::load_weights(*model_, options.init_from);
    spdlog::info(
        "fine-tuning: weights and token groups from {}; optimiser and schedule start afresh",
        options.init_from.string());
  }
  // The token groups: the resumed checkpoint's, or made now from model.grouping (the only place
  // the k-means runs); the other ranks receive rank 0's with its state below.
  if (lead_) tokens_ = std::make_unique<pipeline::Tokens>(*model_, canonical_);
  bn_stats_ = batchnorm_statistics(*model_);
  if (comm_ && tc_.sync_batchnorm) {
    dist::Communicator* comm = comm_;
    const int layers = model::synchronise_batchnorm(
        *model_, std::make_shared<const model::StatsReducer>([comm](torch::Tensor& t) {
          comm->sum_in_place(t, "synchronised BatchNorm (train.sync_batchnorm)");
        }));
    spdlog::info("synchronised BatchNorm: {} layers normalise over all {} ranks' images", layers,
                 procs_);
  }
  if (comm_) {
    st_ = broadcast_state(*comm_, *model_, *optim_, st_);
    if (!lead_) tokens_ = std::make_unique<pipeline::Tokens>(*model_, canonical_);
    spdlog::info("data-parallel training: {} ranks, global batch {} ({} backend)", procs_, world_,
                 comm_->backend());
  }

  if (lead_ && options.resume) drop_rows_after(run_ / "metrics.jsonl", st_.step);
  if (lead_) metrics_log_.emplace(run_ / "metrics.jsonl");
  const int64_t total_steps = int64_t(tc_.epochs) * tc_.iters_per_epoch;
  stop_step_ = options.max_steps >= 0 ? std::min(options.max_steps, total_steps) : total_steps;
  if (lead_) progress_.emplace("train", stop_step_ - st_.step, "step");
  started_ = std::chrono::steady_clock::now();
}

TrainSummary Run::go() {
  const data::ShardedSampler sampler(train_set_->size(), uint64_t(config_.seed), world_);
  const StepContext context{config_, *model_, lpips_.get(), *tokens_, canonical_, device_};
  for (int epoch = st_.epoch; epoch < tc_.epochs && st_.step < stop_step_; ++epoch) {
    const double lr = learning_rate(tc_, epoch);
    set_lr(*optim_, lr);
    // This epoch's samples for this process's ranks (seeded permutation, cycled if shorter).
    auto draw = sampler.draw(epoch, st_.iteration, tc_.iters_per_epoch, ranks_);
    data::Prefetcher loader(train_set_, std::move(draw.order), std::move(draw.seeds),
                            config_.data.workers, config_.data.prefetch);

    for (int it = st_.iteration; it < tc_.iters_per_epoch && st_.step < stop_step_; ++it) {
      const auto t0 = std::chrono::steady_clock::now();
      optim_->zero_grad();
      StepStats stats = accumulate_step(context, loader, ranks_, world_, position(epoch), comm_);
      synchronise_step(comm_, stats, *model_, world_, per_process_, position(epoch));
      torch::nn::utils::clip_grad_value_(model_->parameters(), tc_.grad_clip);
      optim_->step();
      if (comm_) comm_->average(bn_stats_, "the BatchNorm statistics");

      ++st_.step;
      st_.iteration = it + 1;
      st_.epoch = epoch;
      const double seconds =
          std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
      record_step(stats, seconds, lr, epoch, loader);
      if (out_of_time()) {
        spdlog::info("time budget of {} minutes reached at step {}", tc_.max_minutes, st_.step);
        on_lead(
            [&] {
              checkpoint(false);
              plot_training_curve(run_ / "metrics.jsonl", run_ / "training_curve.png");
            },
            "the time-budget checkpoint");
        finish(epoch);
        return summary_;
      }
    }
    if (st_.iteration == tc_.iters_per_epoch) end_of_epoch(epoch);
  }
  on_lead(
      [&] {
        progress_->finish();
        checkpoint(false);
        plot_training_curve(run_ / "metrics.jsonl", run_ / "training_curve.png");
      },
      "the final checkpoint");
  finish(st_.epoch);
  return summary_;
}

// The step's figures into the log window, and a metrics line when one is due.
void Run::record_step(const StepStats& stats, double seconds, double lr, int epoch,
                      const data::Prefetcher& loader) {
  const double loss_value = stats.loss / world_;
  window_.loss += loss_value, window_.psnr += stats.psnr / world_, window_.seconds += seconds;
  window_.rays += int64_t(stats.rays), ++window_.steps;
  if (comm_) window_.allreduce += comm_->allreduce_seconds_last();
  summary_.last_loss = loss_value;
  const bool due = st_.step % tc_.log_every_steps == 0 || st_.step == stop_step_;
  if (lead_ && due) log_step(stats, lr, epoch, loader);
  if (due) window_ = LogWindow();
}

void Run::log_step(const StepStats& stats, double lr, int epoch, const data::Prefetcher& loader) {
  const auto& w = window_;
  pipeline::JsonLine line;
  line.add("step", st_.step)
      .add("epoch", epoch)
      .add("lr", lr)
      .add("loss", w.loss / w.steps)
      .add("mse", stats.mse / world_)
      .add("lpips", lpips_ ? stats.lpips / world_ : NAN)
      .add("psnr", w.psnr / w.steps)
      .add("time_per_step", w.seconds / w.steps)
      .add("rays_per_second", w.rays / w.seconds)
      .add("loader_wait", loader.wait_seconds())
      .add("world_size", procs_)
      .add("global_batch", world_)
      .add("elapsed_s",
           std::chrono::duration<double>(std::chrono::steady_clock::now() - started_).count());
  if (comm_) line.add("allreduce_seconds", w.allreduce / w.steps);
  metrics_log_->write(line);
  char note[96];
  std::snprintf(note, sizeof note, "epoch %d loss %.4f psnr %.2f", epoch, w.loss / w.steps,
                w.psnr / w.steps);
  progress_->advance(w.steps, note);
}

// train.max_minutes: rank 0's clock decides for all.
bool Run::out_of_time() {
  if (tc_.max_minutes <= 0) return false;
  const double minutes =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - started_).count() / 60.0;
  bool out = minutes >= tc_.max_minutes;
  if (comm_) out = comm_->sum({lead_ && out ? 1.0 : 0.0}, "the time budget")[0] > 0;
  return out;
}

// The schedule at the end of an epoch: checkpoint (kept as epoch_NNNN.pt) and validation, each
// every so many epochs and after the last.
void Run::end_of_epoch(int epoch) {
  st_.epoch = epoch + 1;
  st_.iteration = 0;
  const bool last = st_.epoch == tc_.epochs;
  const auto due = [&](int every) { return last || (every > 0 && st_.epoch % every == 0); };
  if (!due(tc_.save_every_epochs) && !((val_set_ || comm_) && due(tc_.val_every_epochs))) return;
  on_lead(
      [&] {
        if (due(tc_.save_every_epochs)) checkpoint(true);
        if (val_set_ && due(tc_.val_every_epochs)) {
          summary_.last_val_psnr = validate(model_, config_, val_set_, *tokens_, canonical_,
                                            device_, val_dir_, st_.epoch, *metrics_log_, st_.step);
          plot_training_curve(run_ / "metrics.jsonl", run_ / "training_curve.png");
        }
      },
      "the checkpoint and validation of epoch " + std::to_string(st_.epoch));
}

void Run::checkpoint(bool keep_epoch_copy) {
  pipeline::save_checkpoint(ckpt_dir_ / "latest.pt", *model_, *optim_, st_);
  last_ckpt_ = ckpt_dir_ / "latest.pt";
  if (keep_epoch_copy) {
    char name[32];
    std::snprintf(name, sizeof name, "epoch_%04d.pt", st_.epoch);
    fs::copy_file(last_ckpt_, ckpt_dir_ / name, fs::copy_options::overwrite_existing);
  }
}

void Run::finish(int epoch) {
  if (!options_.rank_state_dir.empty()) {
    fs::create_directories(options_.rank_state_dir);
    for (int r : ranks_)  // one file per rank this process played (identical for virtual ranks)
      pipeline::save_checkpoint(options_.rank_state_dir / ("rank" + std::to_string(r) + ".pt"),
                                *model_, *optim_, st_);
  }
  if (comm_) comm_->barrier("the end of training");
  summary_.steps = st_.step;
  summary_.epoch = epoch;
  summary_.checkpoint = last_ckpt_;
}

}  // namespace

namespace {

// True when `path` is a checkpoint as this project writes it (a LibTorch archive with a model).
bool ours(const fs::path& path) {
  try {
    pipeline::check_checkpoint_archive(path);
    torch::serialize::InputArchive root, model;
    root.load_from(path.string());
    return root.try_read("model", model);
  } catch (const std::exception&) {
    return false;
  }
}

}  // namespace

void check_init(const Config& config, const fs::path& checkpoint) {
  torch::NoGradGuard no_grad;
  model::TransHuman model(config.model);
  try {
    pipeline::load_weights(*model, checkpoint);
  } catch (const Error& e) {
    if (checkpoint.extension() == ".pth" && ours(checkpoint))
      fail(e.what(), " (a .pth is read as the reference's checkpoint; this file is one of ours, ",
           "written by transhuman-train: name it .pt)");
    throw;
  }
}

TrainSummary train(const Config& config, const torch::Device& device, const TrainOptions& options) {
  return Run(config, device, options).go();
}

}  // namespace th::train
