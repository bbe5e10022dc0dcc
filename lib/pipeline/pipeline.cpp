#include "pipeline/pipeline.hpp"

#include <spdlog/spdlog.h>
#include <torch/torch.h>

#include <chrono>
#include <limits>

#include "core/error.hpp"
#include "metrics/metrics.hpp"
#include "render/progressive.hpp"

namespace th::pipeline {

Tokens::Tokens(model::TransHumanImpl& model, const torch::Tensor& canonical)
    : canonical_(canonical.to(torch::kCPU, torch::kFloat64)) {
  const auto& config = model.config().grouping;
  const auto& stored = model.token_groups();
  if (stored.empty()) {
    auto grouping = body::make_grouping(config);
    if (grouping->is_static())
      labels_ = grouping->labels(canonical_, canonical_);
    else
      grouping_ = std::move(grouping);
    model.set_token_groups({labels_, body::describe(config)});
    spdlog::info("token groups: {}", body::describe(config));
    return;
  }
  if (!stored.labels.defined()) {  // grouped per frame (read_token_groups checked the kind)
    grouping_ = body::make_grouping(config);
    return;
  }
  if (stored.labels.size(0) != canonical_.size(0))
    fail("the model's token groups (", stored.origin, ") label ", stored.labels.size(0),
         " vertices; the body model (data.smpl_model) has ", canonical_.size(0));
  labels_ = stored.labels;
}

torch::Tensor Tokens::labels(const data::FrameBody& body) {
  if (labels_.defined()) return labels_;
  return grouping_->labels(canonical_, body.smpl_vertices.to(torch::kFloat64));
}

model::FrameInputs frame_inputs(const data::Sample& s, const torch::Tensor& canonical,
                                const torch::Tensor& labels, const torch::Device& device) {
  auto f = [&](const torch::Tensor& t) { return t.to(device, torch::kFloat32); };
  model::FrameInputs in;
  in.ref_images = f(s.ref_images);
  in.K = f(s.ref_K);
  in.R = f(s.ref_R);
  in.T = f(s.ref_T);
  in.vertices = f(s.body.vertices);
  in.Rh = f(s.body.Rh);
  in.Th = f(s.body.Th);
  in.A = f(s.body.A);
  in.canonical = canonical.to(device);  // dtype kept: float64 token positions [parity]
  in.visibility = s.visibility.to(device);
  in.labels = labels.to(device, torch::kInt64);
  in.num_tokens = labels.max().item<int64_t>() + 1;
  in.check();
  return in;
}

render::Rays sample_rays(const data::Sample& s, const torch::Device& device) {
  auto f = [&](const torch::Tensor& t) { return t.to(device, torch::kFloat32); };
  return {f(s.ray_o), f(s.ray_d), f(s.near), f(s.far)};
}

model::FrameCache prepare_frame(model::TransHumanImpl& model, const model::FrameInputs& inputs,
                                const RenderConfig& rc) {
  return model.prepare(inputs, rc.cull_distance);
}

int64_t keep_graph_points(const RenderConfig& config) {
  switch (config.train_recompute) {
    case Recompute::always:
      return 0;
    case Recompute::never:
      return std::numeric_limits<int64_t>::max();
    case Recompute::automatic:
      break;
  }
  return model::kKeepGraphPoints;
}

render::RenderResult render(model::TransHumanImpl& model, const model::FrameCache& cache,
                            const render::Rays& rays, const RenderConfig& rc,
                            const RenderPass& pass, render::Profile* profile) {
  const auto* body = cache.geometry.body.get();
  if (pass.training) {
    if (pass.skip_far_points && !body)
      fail("train.skip_far_points: the frame was prepared without a culling distance");
    model::FrameField field(model, cache, rc.train_chunk_points, true, keep_graph_points(rc));
    return render::VolumeRenderer(rc, profile)
        .render(field, rays, true, pass.skip_far_points ? body : nullptr);
  }
  torch::NoGradGuard no_grad;
  model::FrameField field(model, cache, rc.chunk_points, false);
  if (!rc.progressive) return render::VolumeRenderer(rc, profile).render(field, rays, false);
  if (!body) fail("progressive rendering: the frame was prepared without a culling distance");
  return render::render_progressive(field, *body, rays, rc, profile);
}

Rendered render_sample(model::TransHumanImpl& model, const RenderConfig& rc,
                       const model::FrameInputs& inputs, const render::Rays& rays,
                       const RenderPass& pass, render::Profile* profile) {
  Rendered out;
  out.cache = prepare_frame(model, inputs, rc);
  out.result = render(model, out.cache, rays, rc, pass, profile);
  return out;
}

const model::FrameCache& FrameReuse::prepare(model::TransHumanImpl& model,
                                             const model::FrameInputs& inputs,
                                             const RenderConfig& rc) {
  if (valid_ && model::same_inputs(inputs_, inputs)) {
    ++reused_;
    return cache_;
  }
  valid_ = false;
  cache_ = prepare_frame(model, inputs, rc);
  inputs_ = inputs;
  valid_ = true;
  ++prepared_;
  return cache_;
}

ViewResult evaluate_view(model::TransHumanImpl& model, const RenderConfig& rc,
                         const data::Sample& sample, const model::FrameInputs& inputs,
                         metrics::LpipsImpl* lpips, const torch::Device& device,
                         FrameReuse* frames) {
  torch::NoGradGuard no_grad;
  const auto t0 = std::chrono::steady_clock::now();
  const auto rays = sample_rays(sample, device);
  const auto result = frames
                          ? render(model, frames->prepare(model, inputs, rc), rays, rc, kInference)
                          : render_sample(model, rc, inputs, rays, kInference).result;
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  ViewResult r = score_view(result.rgb, result.acc, sample, lpips, device);
  r.seconds = seconds;
  r.stats = result.stats;
  return r;
}

ViewResult score_view(const torch::Tensor& ray_rgb, const torch::Tensor& ray_acc,
                      const data::Sample& sample, metrics::LpipsImpl* lpips,
                      const torch::Device& device) {
  torch::NoGradGuard no_grad;
  ViewResult r;
  const auto rgb = ray_rgb.to(torch::kCPU, torch::kFloat32);
  require_finite_output(rgb, sample.human + " frame " + std::to_string(sample.frame) + " view " +
                                 std::to_string(sample.target_view));
  const auto acc = ray_acc.to(torch::kCPU, torch::kDouble);
  r.acc_max = acc.numel() ? acc.max().item<double>() : 0.0;
  r.rays = acc.numel();
  r.opaque_1e3 = (1 - acc < 1e-3).sum().item<int64_t>();
  r.opaque_1e4 = (1 - acc < 1e-4).sum().item<int64_t>();
  r.psnr = metrics::psnr(rgb, sample.ray_rgb);  // unrendered valid rays are black (METHOD 6)
  const int64_t H = sample.target_image.size(0), W = sample.target_image.size(1);
  r.pred = scatter_image(rgb, sample.ray_pixel, H, W);
  r.gt = sample.target_image * sample.box_mask.unsqueeze(-1);
  const auto crop = metrics::crop_to_valid(r.pred, r.gt, sample.box_mask);
  r.ssim = metrics::ssim(crop.pred.to(torch::kFloat64), crop.gt.to(torch::kFloat64));
  if (lpips) {
    auto nchw = [&](const torch::Tensor& t) {
      return t.permute({2, 0, 1}).unsqueeze(0).to(device) * 2 - 1;
    };
    r.lpips = lpips->forward(nchw(crop.pred), nchw(crop.gt)).item<double>();
  }
  return r;
}

void require_finite_output(const torch::Tensor& rgb, const std::string& what) {
  const int64_t bad = rgb.numel() - torch::isfinite(rgb).sum().item<int64_t>();
  if (bad == 0) return;
  fail(what, ": the network's output is not finite (", bad, " of ", rgb.numel(),
       " values NaN or infinite): weights that are finite but overflow? nothing was scored or "
       "written for it");
}

torch::Tensor scatter_image(const torch::Tensor& rgb, const torch::Tensor& pixel, int64_t height,
                            int64_t width) {
  auto img = torch::zeros({height * width, 3}, rgb.options());
  img.index_put_({pixel.to(rgb.device())}, rgb);
  return img.reshape({height, width, 3});
}

}  // namespace th::pipeline
