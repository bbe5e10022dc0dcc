#include "train/trainer.hpp"

#include <opencv2/imgcodecs.hpp>
#include <spdlog/spdlog.h>
#include <torch/torch.h>

#include <chrono>
#include <cmath>
#include <functional>
#include <numeric>
#include <optional>
#include <random>
#include <sstream>

#include "body/smpl.hpp"
#include "core/error.hpp"
#include "core/progress.hpp"
#include "data/dataset.hpp"
#include "data/sampler.hpp"
#include "dist/communicator.hpp"
#include "io/bytes.hpp"
#include "metrics/lpips.hpp"
#include "metrics/metrics.hpp"
#include "model/checked_load.hpp"
#include "model/checkpoint_import.hpp"
#include "model/encoder.hpp"
#include "train/images.hpp"
#include "train/jsonl.hpp"
#include "train/pipeline.hpp"
#include "train/plot.hpp"
#include "train/schedule.hpp"
#include "train/validation.hpp"

namespace th::train {
namespace fs = std::filesystem;

namespace {

// The checkpoint archive: model weights and buffers, optimiser state and the run's position.
void write_checkpoint(torch::serialize::OutputArchive& root, model::TransHumanImpl& model,
                      torch::optim::Adam& optim, const CheckpointState& st) {
  torch::serialize::OutputArchive m, o;
  model.save(m);
  optim.save(o);
  root.write("model", m);
  model::write_model_config(root, model.config());
  root.write("optimizer", o);
  root.write("epoch", torch::tensor(int64_t(st.epoch)));
  root.write("step", torch::tensor(st.step));
  root.write("iteration", torch::tensor(int64_t(st.iteration)));
}

CheckpointState read_checkpoint(torch::serialize::InputArchive& root, model::TransHumanImpl& model,
                                torch::optim::Adam& optim, const std::string& source) {
  torch::serialize::InputArchive m, o;
  root.read("model", m);
  root.read("optimizer", o);
  model::load_module_checked(model, m, source);
  optim.load(o);
  for (const auto& entry : optim.state()) {  // Adam's moments resume the run: finite too
    const auto& state = static_cast<const torch::optim::AdamParamState&>(*entry.second);
    model::check_finite(state.exp_avg(), source + ": optimiser state exp_avg");
    model::check_finite(state.exp_avg_sq(), source + ": optimiser state exp_avg_sq");
  }
  torch::Tensor epoch, step, iteration;
  root.read("epoch", epoch);
  root.read("step", step);
  root.read("iteration", iteration);
  return {int(epoch.item<int64_t>()), step.item<int64_t>(), int(iteration.item<int64_t>())};
}

// Writes `path` atomically: the archive goes to a temporary file renamed over the target, so a
// checkpoint is never half-written.
void save_checkpoint(const fs::path& path, model::TransHumanImpl& model, torch::optim::Adam& optim,
                     const CheckpointState& st) {
  torch::serialize::OutputArchive root;
  write_checkpoint(root, model, optim, st);
  // Serialised in memory, then written by write_file_atomic: a failing write (disk full) is an
  // error naming the file and leaves no partial file (LibTorch's file writer would throw from its
  // destructor and terminate the process).
  std::ostringstream archive;
  try {
    root.save_to(archive);
  } catch (const c10::Error& e) {
    fail("cannot serialise checkpoint '", path.string(), "': ", e.what_without_backtrace());
  }
  io::detail::write_file_atomic(path, archive.str());
}

CheckpointState load_checkpoint(const fs::path& path, model::TransHumanImpl& model,
                                torch::optim::Adam& optim) {
  if (!fs::exists(path)) fail("cannot resume: '", path.string(), "' does not exist");
  model::check_checkpoint_archive(path);
  torch::serialize::InputArchive root;
  try {
    root.load_from(path.string());
    return read_checkpoint(root, model, optim, path.string());
  } catch (const c10::Error& e) {
    fail("checkpoint '", path.string(), "' cannot be read: ", e.what_without_backtrace());
  }
}

// Data parallelism: every rank starts from rank 0's state (fresh or resumed), sent as the bytes of
// a checkpoint, so no rank needs the run directory.
CheckpointState broadcast_state(dist::Communicator& comm, model::TransHumanImpl& model,
                                torch::optim::Adam& optim, const CheckpointState& st) {
  std::string bytes;
  if (comm.rank() == 0) {
    std::ostringstream out;
    torch::serialize::OutputArchive root;
    write_checkpoint(root, model, optim, st);
    root.save_to(out);
    bytes = out.str();
  }
  comm.broadcast(bytes, "rank 0's weights and optimiser state");
  if (comm.rank() == 0) return st;
  torch::serialize::InputArchive root;
  root.load_from(bytes.data(), bytes.size());
  return read_checkpoint(root, model, optim, "rank 0's weights");
}

// BatchNorm running statistics: averaged over the ranks after each step so every rank holds the
// same buffers (the batch statistics used in training are per sample, SPEC 3.1).
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

}  // namespace

void load_weights(model::TransHumanImpl& model, const fs::path& checkpoint, bool allow_model_mismatch) {
  if (!fs::exists(checkpoint)) fail("checkpoint '", checkpoint.string(), "' does not exist");
  if (checkpoint.extension() == ".pth") {
    const auto report = model::import_reference_checkpoint(model, checkpoint);
    spdlog::info("imported {} tensors of the reference checkpoint {}", report.loaded.size(),
                 checkpoint.string());
    return;
  }
  model::check_checkpoint_archive(checkpoint);
  torch::serialize::InputArchive root, m;
  try {
    root.load_from(checkpoint.string());
    root.read("model", m);
  } catch (const c10::Error& e) {
    fail("checkpoint '", checkpoint.string(), "' cannot be read: ", e.what_without_backtrace());
  }
  // Another model configuration: different shapes fail below naming the parameter; different
  // values of shape-neutral keys (nk, num_tokens, ...) would silently compute something else.
  const auto changed = model::model_config_differences(root, checkpoint, model.config());
  if (!changed.empty()) {
    std::string list;
    for (const auto& c : changed) list += (list.empty() ? "" : "; ") + c;
    if (!allow_model_mismatch)
      fail("checkpoint '", checkpoint.string(), "' was trained with other model settings (", list,
           "): use the run's config.yaml as --config, or eval.model_mismatch=warn to go on anyway");
    spdlog::warn("checkpoint {} was trained with other model settings: {}", checkpoint.string(), list);
  }
  model::load_module_checked(model, m, checkpoint.string());
}

TrainSummary train(const Config& config, const torch::Device& device, const TrainOptions& options) {
  const auto& tc = config.train;
  dist::Communicator* comm = options.comm.get();
  TORCH_CHECK(options.virtual_ranks >= 1, "train: virtual_ranks must be >= 1");
  // Data parallelism: `world` samples per step, one per (virtual) rank; this process computes
  // the samples of `ranks` and rank 0 alone writes into the run directory.
  const int procs = comm ? comm->world_size() : 1, proc = comm ? comm->rank() : 0;
  const int per_process = options.virtual_ranks, world = procs * per_process;
  const bool lead = proc == 0;
  std::vector<int> ranks(static_cast<size_t>(per_process));
  std::iota(ranks.begin(), ranks.end(), proc * per_process);
  auto on_lead = [&](const std::function<void()>& fn, const std::string& what) {
    if (comm) comm->on_lead(fn, what);
    else fn();
  };

  const fs::path run = options.run_dir;
  const fs::path ckpt_dir = run / "checkpoints", val_dir = run / "val";
  if (lead) {
    fs::create_directories(ckpt_dir);
    fs::create_directories(val_dir);
  }

  const auto smpl = data::load_body_model(config.data);
  const auto train_set = std::make_shared<const data::Dataset>(
      config.data, config.data.train_setting, data::Dataset::Mode::Train, smpl);
  if (train_set->size() == 0) fail("training setting '", config.data.train_setting, "' has no samples");
  std::shared_ptr<const data::Dataset> val_set;
  if (tc.val_views > 0 && lead)
    val_set = std::make_shared<const data::Dataset>(config.data, config.data.test_setting,
                                                    data::Dataset::Mode::Test, smpl);

  torch::manual_seed(uint64_t(config.seed));
  model::TransHuman model(config.model, config.render.cull_distance);
  // The constructor loads model.encoder.pretrained (and logs either way).
  model->to(device);
  torch::optim::Adam optim(model->parameters(), torch::optim::AdamOptions(tc.lr)
                                                    .betas({tc.beta1, tc.beta2})
                                                    .eps(tc.eps));
  std::shared_ptr<metrics::LpipsImpl> lpips;
  if (tc.lpips_weight > 0) lpips = metrics::try_load_lpips(tc.lpips_weights, device, "the perceptual loss");

  const torch::Tensor canonical = smpl->v_template;  // float64: token positions [parity]
  Tokens tokens(config.model.grouping, smpl->v_template);

  CheckpointState st;
  fs::path last_ckpt;
  if (options.resume && lead) {
    last_ckpt = ckpt_dir / "latest.pt";
    st = load_checkpoint(last_ckpt, *model, optim);
    spdlog::info("resumed from {} at epoch {}, step {}", last_ckpt.string(), st.epoch, st.step);
  }
  const auto bn_stats = batchnorm_statistics(*model);
  if (comm) {
    st = broadcast_state(*comm, *model, optim, st);
    spdlog::info("data-parallel training: {} ranks, global batch {} ({} backend)", procs, world,
                 comm->backend());
  }

  std::optional<JsonlWriter> metrics_log;
  if (lead) metrics_log.emplace(run / "metrics.jsonl");
  const int64_t total_steps = int64_t(tc.epochs) * tc.iters_per_epoch;
  const int64_t stop_step = options.max_steps >= 0 ? std::min(options.max_steps, total_steps) : total_steps;
  std::optional<Progress> progress;
  if (lead) progress.emplace("train", stop_step - st.step, "step");
  const auto started = std::chrono::steady_clock::now();
  auto minutes = [&] {
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - started).count() / 60.0;
  };
  auto checkpoint = [&](const CheckpointState& s, bool keep_epoch_copy) {
    save_checkpoint(ckpt_dir / "latest.pt", *model, optim, s);
    last_ckpt = ckpt_dir / "latest.pt";
    if (keep_epoch_copy) {
      char name[32];
      std::snprintf(name, sizeof name, "epoch_%04d.pt", s.epoch);
      fs::copy_file(last_ckpt, ckpt_dir / name, fs::copy_options::overwrite_existing);
    }
  };
  auto finish = [&](TrainSummary& summary, int epoch) {
    if (!options.rank_state_dir.empty()) {
      fs::create_directories(options.rank_state_dir);
      for (int r : ranks)  // one file per rank this process played (identical for virtual ranks)
        save_checkpoint(options.rank_state_dir / ("rank" + std::to_string(r) + ".pt"), *model, optim, st);
    }
    if (comm) comm->barrier("the end of training");
    summary.steps = st.step;
    summary.epoch = epoch;
    summary.checkpoint = last_ckpt;
  };

  TrainSummary summary;
  double loss_sum = 0, psnr_sum = 0, time_sum = 0, allreduce_sum = 0;
  int64_t rays_sum = 0, logged = 0;
  const int P = config.data.patch.count, S = config.data.patch.size;
  const data::ShardedSampler sampler(train_set->size(), uint64_t(config.seed), world);

  for (int epoch = st.epoch; epoch < tc.epochs && st.step < stop_step; ++epoch) {
    const double lr = learning_rate(tc, epoch);
    set_lr(optim, lr);
    // This epoch's samples for this process's ranks (seeded permutation, cycled if shorter).
    auto draw = sampler.draw(epoch, st.iteration, tc.iters_per_epoch, ranks);
    data::Prefetcher loader(train_set, std::move(draw.order), std::move(draw.seeds),
                            config.data.workers, config.data.prefetch);

    for (int it = st.iteration; it < tc.iters_per_epoch && st.step < stop_step; ++it) {
      const auto t0 = std::chrono::steady_clock::now();
      // Sums over this process's samples (over all ranks after the reduction below).
      double step_loss = 0, step_mse = 0, step_lpips = 0, step_psnr = 0, step_rays = 0;
      std::string bad_loss;  // the error of a non-finite loss on this process
      optim.zero_grad();
      for (int j = 0; j < per_process; ++j) {
        const data::Sample sample = loader.next();
        // Stratified jitter, per sample of the global batch (with one rank: per step).
        torch::manual_seed(data::mix_seed(uint64_t(config.seed) + uint64_t(st.step) * uint64_t(world) +
                                          uint64_t(ranks[size_t(j)])));
        model->train();
        const auto inputs = frame_inputs(sample, canonical, tokens.labels(sample.body), device);
        const auto rays = sample_rays(sample, device);
        const auto rendered = render_sample(*model, config.render, inputs, rays, true, tc.skip_far_points);
        const auto& rgb = rendered.result.rgb;

        // Patches: rendered colours in their slots, black where no ray was rendered (SPEC 5).
        auto canvas = torch::zeros({int64_t(P) * S * S, 3}, rgb.options());
        canvas.index_put_({sample.ray_patch_index.to(device)}, rgb);
        canvas = canvas.reshape({P, S, S, 3}).permute({0, 3, 1, 2});
        const auto target = sample.patch_rgb.to(device);
        const auto mse = torch::mse_loss(canvas, target);
        torch::Tensor loss = mse, perceptual;
        if (lpips) {
          perceptual = lpips->forward(canvas * 2 - 1, target * 2 - 1).mean();
          loss = loss + tc.lpips_weight * perceptual;
        }
        const double loss_value = loss.item<double>();
        if (!std::isfinite(loss_value)) {
          std::ostringstream msg;
          msg << "the loss became " << loss_value << " at step " << st.step << " (epoch " << epoch
              << (comm ? ", rank " + std::to_string(proc) : std::string()) << "); last good checkpoint: "
              << (last_ckpt.empty() ? std::string("none yet") : last_ckpt.string())
              << " (try a lower train.lr or check the data of sample '" << sample.human << "' frame "
              << sample.frame << ")";
          if (!comm) fail(msg.str());
          bad_loss = msg.str();  // the other ranks must learn of it before anyone steps
        } else {
          loss.backward();
        }
        step_loss += loss_value;
        step_mse += mse.item<double>();
        step_lpips += perceptual.defined() ? perceptual.item<double>() : NAN;
        step_psnr += metrics::psnr(rgb.detach().cpu(), sample.ray_rgb);
        step_rays += double(rays.size());
      }
      if (comm) {
        // One small reduction: the step's statistics and whether any rank saw a non-finite loss.
        const auto sums = comm->sum({step_loss, step_mse, step_lpips, step_psnr, step_rays,
                                     bad_loss.empty() ? 0.0 : 1.0}, "the step statistics");
        if (!bad_loss.empty()) fail(bad_loss);
        if (sums[5] > 0)
          fail("the loss became non-finite on ", int(sums[5]), " other rank(s) at step ", st.step,
               " (epoch ", epoch, "); see their error; last good checkpoint: ",
               last_ckpt.empty() ? std::string("none yet") : last_ckpt.string());
        step_loss = sums[0], step_mse = sums[1], step_lpips = sums[2], step_psnr = sums[3], step_rays = sums[4];
        comm->average_gradients(model->parameters(), world);
      } else if (per_process > 1) {
        for (auto& p : model->parameters())
          if (p.grad().defined()) p.mutable_grad().div_(per_process);
      }
      torch::nn::utils::clip_grad_value_(model->parameters(), tc.grad_clip);
      optim.step();
      if (comm) comm->average(bn_stats, "the BatchNorm statistics");

      ++st.step;
      st.iteration = it + 1;
      st.epoch = epoch;
      const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
      const double loss_value = step_loss / world;
      loss_sum += loss_value, psnr_sum += step_psnr / world, time_sum += seconds;
      rays_sum += int64_t(step_rays), ++logged;
      if (comm) allreduce_sum += comm->allreduce_seconds_last();
      summary.last_loss = loss_value;
      if (lead && (st.step % tc.log_every_steps == 0 || st.step == stop_step)) {
        JsonLine line;
        line.add("step", st.step).add("epoch", epoch).add("lr", lr).add("loss", loss_sum / logged)
            .add("mse", step_mse / world)
            .add("lpips", lpips ? step_lpips / world : NAN)
            .add("psnr", psnr_sum / logged).add("time_per_step", time_sum / logged)
            .add("rays_per_second", rays_sum / time_sum)
            .add("loader_wait", loader.wait_seconds())
            .add("world_size", procs).add("global_batch", world);
        if (comm) line.add("allreduce_seconds", allreduce_sum / logged);
        metrics_log->write(line);
        char note[96];
        std::snprintf(note, sizeof note, "epoch %d loss %.4f psnr %.2f", epoch, loss_sum / logged, psnr_sum / logged);
        progress->advance(logged, note);
      }
      if (st.step % tc.log_every_steps == 0 || st.step == stop_step) {
        loss_sum = psnr_sum = time_sum = allreduce_sum = 0;
        rays_sum = logged = 0;
      }
      if (tc.max_minutes > 0) {
        bool out_of_time = minutes() >= tc.max_minutes;  // rank 0's clock decides for all
        if (comm) out_of_time = comm->sum({lead && out_of_time ? 1.0 : 0.0}, "the time budget")[0] > 0;
        if (out_of_time) {
          spdlog::info("time budget of {} minutes reached at step {}", tc.max_minutes, st.step);
          on_lead([&] {
            checkpoint(st, false);
            plot_training_curve(run / "metrics.jsonl", run / "training_curve.png");
          }, "the time-budget checkpoint");
          finish(summary, epoch);
          return summary;
        }
      }
    }
    if (st.iteration == tc.iters_per_epoch) {  // epoch complete
      st.epoch = epoch + 1;
      st.iteration = 0;
      const bool last = st.epoch == tc.epochs;
      const auto due = [&](int every) { return last || (every > 0 && st.epoch % every == 0); };
      if (due(tc.save_every_epochs) || (val_set && due(tc.val_every_epochs)) || (comm && due(tc.val_every_epochs)))
        on_lead([&] {
          if (due(tc.save_every_epochs)) checkpoint(st, true);
          if (val_set && due(tc.val_every_epochs)) {
            summary.last_val_psnr = validate(*model, config, *val_set, tokens, canonical, device,
                                             val_dir, st.epoch, *metrics_log, st.step);
            plot_training_curve(run / "metrics.jsonl", run / "training_curve.png");
          }
        }, "the checkpoint and validation of epoch " + std::to_string(st.epoch));
    }
  }
  on_lead([&] {
    progress->finish();
    checkpoint(st, false);
    plot_training_curve(run / "metrics.jsonl", run / "training_curve.png");
  }, "the final checkpoint");
  finish(summary, st.epoch);
  return summary;
}

}  // namespace th::train
