#include "train/step.hpp"

#include <torch/torch.h>

#include <cmath>
#include <sstream>

#include "core/error.hpp"
#include "data/dataset.hpp"
#include "data/sampler.hpp"
#include "dist/communicator.hpp"
#include "metrics/metrics.hpp"
#include "pipeline/pipeline.hpp"
#include "train/loss.hpp"

namespace th::train {
namespace {

std::string last_good(const StepPosition& where) {
  return where.last_checkpoint.empty() ? std::string("none yet") : where.last_checkpoint;
}

}  // namespace

StepStats accumulate_step(const StepContext& c, data::Prefetcher& loader,
                          const std::vector<int>& ranks, int world, const StepPosition& where,
                          dist::Communicator* comm) {
  StepStats stats;
  const uint64_t seed = uint64_t(c.config.seed);
  for (const int rank : ranks) {
    const data::Sample sample = loader.next();
    // Stratified jitter, per sample of the global batch (with one rank: per step).
    torch::manual_seed(
        data::mix_seed(seed + uint64_t(where.step) * uint64_t(world) + uint64_t(rank)));
    c.model.train();
    const auto inputs =
        pipeline::frame_inputs(sample, c.canonical, c.tokens.labels(sample.body), c.device);
    const auto rays = pipeline::sample_rays(sample, c.device);
    const auto rendered =
        pipeline::render_sample(c.model, c.config.render, inputs, rays,
                                {/*training=*/true, c.config.train.skip_far_points});
    const auto& rgb = rendered.result.rgb;
    const auto loss = patch_loss(rgb, sample.ray_patch_index, sample.patch_rgb, c.lpips,
                                 c.config.train.lpips_weight);
    const double loss_value = loss.total.item<double>();
    if (!std::isfinite(loss_value)) {
      std::ostringstream msg;
      msg << "the loss became " << loss_value << " at step " << where.step << " (epoch "
          << where.epoch
          << (where.rank >= 0 ? ", rank " + std::to_string(where.rank) : std::string())
          << "); last good checkpoint: " << last_good(where)
          << " (try a lower train.lr or check the data of sample '" << sample.human << "' frame "
          << sample.frame << ")";
      if (!comm) fail(msg.str());
      stats.bad_loss = msg.str();
    } else if (!loss.total.requires_grad()) {
      // No sample point lay inside the body's box: the image has nothing to learn from.
      std::ostringstream msg;
      msg << "sample '" << sample.human << "' frame " << sample.frame << ", target view "
          << sample.target_view << ": no ray of its patches meets the body's box at step "
          << where.step << " (is the body inside that view? check its calibration and mask)";
      if (!comm) fail(msg.str());
      stats.bad_loss = msg.str();
    }
    // Every rank learns of a failed sample before any back-propagates: the backward pass of
    // synchronised BatchNorm is a collective that every rank must join. A failure anywhere
    // ends the step everywhere (synchronise_step names it).
    if (comm && comm->sum({stats.bad_loss.empty() ? 0.0 : 1.0}, "the step's sample check")[0] > 0) {
      if (stats.bad_loss.empty()) stats.peer_failed = true;
      break;
    }
    if (stats.bad_loss.empty()) loss.total.backward();
    stats.loss += loss_value;
    stats.mse += loss.mse.item<double>();
    stats.lpips += loss.perceptual.defined() ? loss.perceptual.item<double>() : NAN;
    stats.psnr += metrics::psnr(rgb.detach().cpu(), sample.ray_rgb);
    stats.rays += double(rays.size());
  }
  return stats;
}

void synchronise_step(dist::Communicator* comm, StepStats& s, model::TransHumanImpl& model,
                      int world, int per_process, const StepPosition& where) {
  if (!comm) {
    if (per_process > 1)
      for (auto& p : model.parameters())
        if (p.grad().defined()) p.mutable_grad().div_(per_process);
    return;
  }
  const auto sums =
      comm->sum({s.loss, s.mse, s.lpips, s.psnr, s.rays, s.bad_loss.empty() ? 0.0 : 1.0},
                "the step statistics");
  if (!s.bad_loss.empty()) fail(s.bad_loss);
  if (sums[5] > 0)
    fail("a sample failed (non-finite loss or no body in view) on ", int(sums[5]),
         " other rank(s) at step ", where.step, " (epoch ", where.epoch,
         "); see their error; last good checkpoint: ", last_good(where));
  s.loss = sums[0], s.mse = sums[1], s.lpips = sums[2], s.psnr = sums[3], s.rays = sums[4];
  comm->average_gradients(model.parameters(), world);
}

}  // namespace th::train
