#include "app/summary.hpp"

#include <spdlog/spdlog.h>

namespace th::app {

void print_summary(const RunContext& ctx) {
  const Config& c = ctx.config;
  spdlog::info("data: {} at '{}' | split file {} | train '{}' / test '{}' | ratio {}", c.data.dataset,
               c.data.root, c.data.split_file, c.data.train_setting, c.data.test_setting,
               c.data.ratio);
  const auto& m = c.model;
  spdlog::info("model: {} | grouping {} (Nt {}) | TransHE {} ({} PE) | DPaRF Nk {} ({}) | FDI a={} "
               "h={} rgb={}",
               m.representation, m.grouping.kind, m.grouping.num_tokens,
               m.transhe.enabled ? "on" : "off", m.transhe.position, m.dparf.nk,
               m.dparf.coordinate, m.fdi.appearance, m.fdi.human, m.fdi.raw_rgb);
  spdlog::info("render: {} samples/ray | progressive {} | chunk {} points", c.render.samples,
               c.render.progressive, c.render.chunk_points);
  spdlog::info("train: {} epochs x {} iters | lr {} (warm-up {} epochs, cosine to {}) | clip {} | "
               "LPIPS weight {}",
               c.train.epochs, c.train.iters_per_epoch, c.train.lr, c.train.warmup_epochs,
               c.train.min_lr, c.train.grad_clip, c.train.lpips_weight);
}

}  // namespace th::app
