#include "app/summary.hpp"

#include <spdlog/spdlog.h>

#include "bake/bake.hpp"
#include "body/grouping.hpp"
#include "body/smpl.hpp"
#include "core/error.hpp"
#include "core/runtime.hpp"
#include "data/dataset.hpp"
#include "model/transhuman.hpp"
#include "pipeline/checkpoint.hpp"

namespace th::app {

void load_first_training_sample(const Config& c) {
  data::Dataset ds(c.data, c.data.train_setting, data::Dataset::Mode::Train,
                   data::load_body_model(c.data));
  if (ds.size() == 0) fail("setting '", c.data.train_setting, "' lists no samples");
  ds.load(0, uint64_t(c.seed));
}

void print_summary(const RunContext& ctx, bool dry_run, const std::string& checkpoint) {
  const Config& c = ctx.config;
  spdlog::info(
      "data: {} at '{}' | split file {} | train '{}' / test '{}' | ratio {}",
      config::name_of(c.data.dataset), c.data.root,
      c.data.split_file.empty() ? std::string("none (every person and frame)") : c.data.split_file,
      c.data.train_setting, c.data.test_setting, c.data.ratio);
  // The data index: splits and annots only (no images are read), unless this is a dry run.
  try {
    auto smpl = data::load_body_model(c.data);
    spdlog::info("body model: {} vertices, {} faces", smpl->num_vertices(), smpl->faces.size(0));
    bool training = true;  // the training setting is loaded as training loads it (patches)
    for (const auto& setting : {c.data.train_setting, c.data.test_setting}) {
      const bool as_training = training;
      data::Dataset ds(c.data, setting,
                       training ? data::Dataset::Mode::Train : data::Dataset::Mode::Test, smpl);
      training = false;
      spdlog::info("  '{}': {} samples from {} humans", setting, ds.size(), ds.humans().size());
      if (!dry_run) continue;
      if (ds.size() == 0 && !as_training) {
        // Renders need no target view; transhuman-eval refuses such a setting by name.
        spdlog::info("  '{}': no target view (new views only)", setting);
        continue;
      }
      if (ds.size() == 0) fail("setting '", setting, "' lists no samples");
      const auto sample = ds.load(0, uint64_t(c.seed));
      spdlog::info("  '{}': sample 0 loaded ({} x {} target, {} reference views)", setting,
                   sample.target_image.size(1), sample.target_image.size(0),
                   sample.ref_images.size(0));
    }
  } catch (const Error& e) {
    if (dry_run) throw;
    spdlog::warn("data not available: {}", e.what());
  }
  const auto& m = c.model;
  spdlog::info(
      "model: {} | grouping {} (Nt {}) | TransHE {} ({} PE) | DPaRF Nk {} ({}) | FDI a={} "
      "h={} rgb={}",
      config::name_of(m.representation), config::name_of(m.grouping.kind), m.grouping.num_tokens,
      m.transhe.enabled ? "on" : "off", config::name_of(m.transhe.position), m.dparf.nk,
      config::name_of(m.dparf.coordinate), m.fdi.appearance, m.fdi.human, m.fdi.raw_rgb);
  model::TransHuman net(m);
  if (dry_run && !checkpoint.empty()) {
    pipeline::load_weights(*net, checkpoint, c.eval.model_mismatch == MismatchPolicy::warn);
    spdlog::info("checkpoint {} read and checked", checkpoint);
  }
  for (const auto& p : model::parameter_counts(*net))
    spdlog::info("  parameters {:<44} {:>11}", p.module, with_commas(p.count));
  spdlog::info("render: {} samples/ray | progressive {} | chunk {} points", c.render.samples,
               c.render.progressive, c.render.chunk_points);
  auto renderer = [&](ViewRenderer r) { return bake::renderer_label(r, c.eval.bake_voxel); };
  spdlog::info(
      "views scored by: evaluation {} (eval.renderer) | validation {} (train.val_renderer)",
      renderer(c.eval.renderer), renderer(c.train.val_renderer));
  model::select_products(c.precision, c.fp32_products, runtime::select_device(c.device));
  spdlog::info(
      "train: {} epochs x {} iters | lr {} (warm-up {} epochs, cosine to {}) | clip {} | "
      "LPIPS weight {}",
      c.train.epochs, c.train.iters_per_epoch, c.train.lr, c.train.warmup_epochs, c.train.min_lr,
      c.train.grad_clip, c.train.lpips_weight);
  spdlog::info("  a step: one target image, {} patches of {} x {} rays, {} samples per ray",
               c.data.patch.count, c.data.patch.size, c.data.patch.size, c.render.samples);
  // The files the config needs besides the data (start_run has refused a missing one).
  auto file = [](const std::string& path, const std::string& empty) {
    return path.empty() ? empty : "'" + path + "'";
  };
  const auto& g = m.grouping;
  spdlog::info(
      "files: body model {} | encoder start {} | LPIPS weights: training {}, evaluation {}",
      file(c.data.smpl_model, "'<data.root>/smpl_model.npz'"),
      file(m.encoder.pretrained, "random (model.encoder.pretrained empty)"),
      c.train.lpips_weight > 0 ? file(c.train.lpips_weights, "none (term off)")
                               : "term off (weight 0)",
      file(c.eval.lpips_weights, "none (LPIPS not reported)"));
  spdlog::info("token groups: {}; a checkpoint carries its own", body::describe(g));
}

}  // namespace th::app
