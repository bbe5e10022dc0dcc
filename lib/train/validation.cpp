#include "train/validation.hpp"

#include <spdlog/spdlog.h>
#include <torch/torch.h>

#include <chrono>
#include <memory>

#include "bake/bake.hpp"
#include "inference/session.hpp"
#include "pipeline/images.hpp"
#include "video/frame_writer.hpp"

namespace th::train {

double validate(model::TransHuman model, const Config& config,
                const std::shared_ptr<const data::Dataset>& val_set, pipeline::Tokens& tokens,
                const torch::Tensor& canonical, const torch::Device& device,
                const std::filesystem::path& dir, int epoch, pipeline::JsonlWriter& log,
                int64_t step) {
  const size_t n = std::min<size_t>(size_t(config.train.val_views), val_set->size());
  if (n == 0) return 0.0;
  model->eval();
  const bool baked = config.train.val_renderer == ViewRenderer::baked;
  const std::string renderer =
      bake::renderer_label(config.train.val_renderer, config.eval.bake_voxel);
  // The baked renderer: a session over the network as it is now, its frames baked.
  std::unique_ptr<inference::Session> session;
  std::unique_ptr<bake::SampleBakes> bakes;
  if (baked) {
    session = std::make_unique<inference::Session>(config, device, model, val_set, canonical,
                                                   "training step " + std::to_string(step));
    bake::BakeOptions options;
    options.voxel = config.eval.bake_voxel;
    bakes = std::make_unique<bake::SampleBakes>(*session, options);
  }
  const auto start = std::chrono::steady_clock::now();
  double psnr_sum = 0, acc_max = 0;
  for (size_t k = 0; k < n; ++k) {
    const size_t index = k * val_set->size() / n;  // spread over the split
    const data::Sample s = val_set->load(index, 0);
    pipeline::ViewResult r;
    if (bakes) {
      const auto view = bakes->render(s);
      r = pipeline::score_view(view.ray_rgb, view.ray_acc, s, nullptr, device);
    } else {
      const auto inputs = pipeline::frame_inputs(s, canonical, tokens.labels(s.body), device);
      r = pipeline::evaluate_view(*model, config.render, s, inputs, nullptr, device);
    }
    psnr_sum += r.psnr;
    acc_max = std::max(acc_max, r.acc_max);
    char name[48];
    std::snprintf(name, sizeof name, "epoch_%04d_%zu.png", epoch, k);
    video::write_png(dir / name,
                     pipeline::panel({video::to_bgr8(r.pred), video::to_bgr8(r.gt),
                                      pipeline::error_map(r.pred, r.gt)},
                                     {baked ? renderer : "render", "ground truth", "error"}));
  }
  model->train();
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  const double psnr = psnr_sum / double(n);
  log.write(pipeline::JsonLine()
                .add("step", step)
                .add("epoch", epoch)
                .add("val_psnr", psnr)
                .add("val_acc_max", acc_max)
                .add("val_renderer", renderer)
                .add("val_seconds", seconds));
  spdlog::info(
      "validation after epoch {}: PSNR {:.2f} dB over {} views, {} renderer, {:.1f} s "
      "(images in {})",
      epoch, psnr, n, renderer, seconds, dir.string());
  if (acc_max < 0.05)
    spdlog::warn(
        "validation renders are empty (accumulated opacity <= {:.3f} everywhere): the model "
        "has collapsed to an empty field. Try: a lower train.lr or a longer warm-up "
        "(train.warmup_epochs), check that the masks and the SMPL fits line up with the "
        "images (transhuman-synth's contact sheet / the data checks), and that "
        "data.ratio and the cameras agree.",
        acc_max);
  return psnr;
}

}  // namespace th::train
