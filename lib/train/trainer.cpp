#include "train/trainer.hpp"

#include <opencv2/imgcodecs.hpp>
#include <spdlog/spdlog.h>
#include <torch/torch.h>

#include <chrono>
#include <cmath>
#include <numeric>
#include <random>

#include "body/smpl.hpp"
#include "core/error.hpp"
#include "core/progress.hpp"
#include "data/dataset.hpp"
#include "metrics/lpips.hpp"
#include "metrics/metrics.hpp"
#include "model/checkpoint_import.hpp"
#include "train/images.hpp"
#include "train/jsonl.hpp"
#include "train/pipeline.hpp"
#include "train/plot.hpp"
#include "train/schedule.hpp"
#include "train/validation.hpp"

namespace th::train {
namespace fs = std::filesystem;

namespace {

// SplitMix64: decorrelated seeds for (run seed, epoch, iteration) and per step.
uint64_t mix(uint64_t x) {
  x += 0x9E3779B97F4A7C15ull;
  x = (x ^ (x >> 30)) * 0xBF58476D1CE4E5B9ull;
  x = (x ^ (x >> 27)) * 0x94D049BB133111EBull;
  return x ^ (x >> 31);
}

// Writes `path` atomically: the archive goes to a temporary file renamed over the target, so a
// checkpoint is never half-written.
void save_checkpoint(const fs::path& path, model::TransHumanImpl& model, torch::optim::Adam& optim,
                     const CheckpointState& st) {
  torch::serialize::OutputArchive root, m, o;
  model.save(m);
  optim.save(o);
  root.write("model", m);
  root.write("optimizer", o);
  root.write("epoch", torch::tensor(int64_t(st.epoch)));
  root.write("step", torch::tensor(st.step));
  root.write("iteration", torch::tensor(int64_t(st.iteration)));
  const fs::path tmp = path.string() + ".tmp";
  try {
    root.save_to(tmp.string());
  } catch (const c10::Error& e) {
    fail("cannot write checkpoint '", tmp.string(), "': ", e.what_without_backtrace());
  }
  fs::rename(tmp, path);
}

CheckpointState load_checkpoint(const fs::path& path, model::TransHumanImpl& model,
                                torch::optim::Adam& optim) {
  if (!fs::exists(path)) fail("cannot resume: '", path.string(), "' does not exist");
  torch::serialize::InputArchive root, m, o;
  try {
    root.load_from(path.string());
    root.read("model", m);
    root.read("optimizer", o);
  } catch (const c10::Error& e) {
    fail("checkpoint '", path.string(), "' cannot be read: ", e.what_without_backtrace());
  }
  model.load(m);
  optim.load(o);
  torch::Tensor epoch, step, iteration;
  root.read("epoch", epoch);
  root.read("step", step);
  root.read("iteration", iteration);
  return {int(epoch.item<int64_t>()), step.item<int64_t>(), int(iteration.item<int64_t>())};
}

void set_lr(torch::optim::Adam& optim, double lr) {
  for (auto& group : optim.param_groups())
    static_cast<torch::optim::AdamOptions&>(group.options()).lr(lr);
}

}  // namespace

void load_weights(model::TransHumanImpl& model, const fs::path& checkpoint) {
  if (!fs::exists(checkpoint)) fail("checkpoint '", checkpoint.string(), "' does not exist");
  if (checkpoint.extension() == ".pth") {
    const auto report = model::import_reference_checkpoint(model, checkpoint);
    spdlog::info("imported {} tensors of the reference checkpoint {}", report.loaded.size(),
                 checkpoint.string());
    return;
  }
  torch::serialize::InputArchive root, m;
  try {
    root.load_from(checkpoint.string());
    root.read("model", m);
  } catch (const c10::Error& e) {
    fail("checkpoint '", checkpoint.string(), "' cannot be read: ", e.what_without_backtrace());
  }
  model.load(m);
}

TrainSummary train(const Config& config, const torch::Device& device, const TrainOptions& options) {
  const auto& tc = config.train;
  const fs::path run = options.run_dir;
  const fs::path ckpt_dir = run / "checkpoints", val_dir = run / "val";
  fs::create_directories(ckpt_dir);
  fs::create_directories(val_dir);

  const auto smpl = data::load_body_model(config.data);
  const auto train_set = std::make_shared<const data::Dataset>(
      config.data, config.data.train_setting, data::Dataset::Mode::Train, smpl);
  if (train_set->size() == 0) fail("training setting '", config.data.train_setting, "' has no samples");
  std::shared_ptr<const data::Dataset> val_set;
  if (tc.val_views > 0)
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

  const torch::Tensor canonical = smpl->v_template.to(torch::kFloat32);
  Tokens tokens(config.model.grouping, smpl->v_template);

  CheckpointState st;
  fs::path last_ckpt;
  if (options.resume) {
    last_ckpt = ckpt_dir / "latest.pt";
    st = load_checkpoint(last_ckpt, *model, optim);
    spdlog::info("resumed from {} at epoch {}, step {}", last_ckpt.string(), st.epoch, st.step);
  }

  JsonlWriter metrics_log(run / "metrics.jsonl");
  const int64_t total_steps = int64_t(tc.epochs) * tc.iters_per_epoch;
  const int64_t stop_step = options.max_steps >= 0 ? std::min(options.max_steps, total_steps) : total_steps;
  Progress progress("train", stop_step - st.step, "step");
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

  TrainSummary summary;
  double loss_sum = 0, psnr_sum = 0, time_sum = 0;
  int64_t rays_sum = 0, logged = 0;
  const int P = config.data.patch.count, S = config.data.patch.size;

  for (int epoch = st.epoch; epoch < tc.epochs && st.step < stop_step; ++epoch) {
    const double lr = learning_rate(tc, epoch);
    set_lr(optim, lr);
    // This epoch's samples: a seeded permutation of the dataset (cycled if shorter).
    std::mt19937_64 erng(mix(uint64_t(config.seed) ^ mix(uint64_t(epoch))));
    std::vector<size_t> perm(train_set->size());
    std::iota(perm.begin(), perm.end(), 0);
    std::shuffle(perm.begin(), perm.end(), erng);
    std::vector<size_t> order;
    std::vector<uint64_t> seeds;
    for (int it = st.iteration; it < tc.iters_per_epoch; ++it) {
      order.push_back(perm[size_t(it) % perm.size()]);
      seeds.push_back(mix(uint64_t(config.seed) * 1000003ull + uint64_t(epoch) * 7919ull + uint64_t(it)));
    }
    data::Prefetcher loader(train_set, order, seeds, config.data.workers, config.data.prefetch);

    for (int it = st.iteration; it < tc.iters_per_epoch && st.step < stop_step; ++it) {
      const auto t0 = std::chrono::steady_clock::now();
      const data::Sample sample = loader.next();
      torch::manual_seed(mix(uint64_t(config.seed) + uint64_t(st.step)));  // stratified jitter
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
      if (!std::isfinite(loss_value))
        fail("the loss became ", loss_value, " at step ", st.step, " (epoch ", epoch, "); last good checkpoint: ",
             last_ckpt.empty() ? std::string("none yet") : last_ckpt.string(),
             " (try a lower train.lr or check the data of sample '", sample.human, "' frame ", sample.frame, ")");
      optim.zero_grad();
      loss.backward();
      torch::nn::utils::clip_grad_value_(model->parameters(), tc.grad_clip);
      optim.step();

      ++st.step;
      st.iteration = it + 1;
      st.epoch = epoch;
      const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
      const double batch_psnr =
          metrics::psnr(rgb.detach().cpu(), sample.ray_rgb);
      loss_sum += loss_value, psnr_sum += batch_psnr, time_sum += seconds;
      rays_sum += rays.size(), ++logged;
      summary.last_loss = loss_value;
      if (st.step % tc.log_every_steps == 0 || st.step == stop_step) {
        JsonLine line;
        line.add("step", st.step).add("epoch", epoch).add("lr", lr).add("loss", loss_sum / logged)
            .add("mse", mse.item<double>())
            .add("lpips", perceptual.defined() ? perceptual.item<double>() : NAN)
            .add("psnr", psnr_sum / logged).add("time_per_step", time_sum / logged)
            .add("rays_per_second", rays_sum / time_sum)
            .add("loader_wait", loader.wait_seconds());
        metrics_log.write(line);
        char note[96];
        std::snprintf(note, sizeof note, "epoch %d loss %.4f psnr %.2f", epoch, loss_sum / logged, psnr_sum / logged);
        progress.advance(logged, note);
        loss_sum = psnr_sum = time_sum = 0;
        rays_sum = logged = 0;
      }
      if (tc.max_minutes > 0 && minutes() >= tc.max_minutes) {
        spdlog::info("time budget of {} minutes reached at step {}", tc.max_minutes, st.step);
        checkpoint(st, false);
        plot_training_curve(run / "metrics.jsonl", run / "training_curve.png");
        summary.steps = st.step;
        summary.epoch = epoch;
        summary.checkpoint = last_ckpt;
        return summary;
      }
    }
    if (st.iteration == tc.iters_per_epoch) {  // epoch complete
      st.epoch = epoch + 1;
      st.iteration = 0;
      const bool last = st.epoch == tc.epochs;
      const auto due = [&](int every) { return last || (every > 0 && st.epoch % every == 0); };
      if (due(tc.save_every_epochs)) checkpoint(st, true);
      if (val_set && due(tc.val_every_epochs))
      {
        summary.last_val_psnr = validate(*model, config, *val_set, tokens, canonical, device,
                                         val_dir, st.epoch, metrics_log, st.step);
        plot_training_curve(run / "metrics.jsonl", run / "training_curve.png");
      }
    }
  }
  progress.finish();
  checkpoint(st, false);
  plot_training_curve(run / "metrics.jsonl", run / "training_curve.png");
  summary.steps = st.step;
  summary.epoch = st.epoch;
  summary.checkpoint = last_ckpt;
  return summary;
}

}  // namespace th::train
