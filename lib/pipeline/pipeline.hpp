#pragma once
// The glue between the stages (STYLE: data flows one way): a dataset sample becomes the
// network's frame inputs (with its token grouping), the network a radiance field, the renderer
// its image, the image a scored view. Shared by training, evaluation and inference, which use
// this library rather than each other.

#include <torch/types.h>

#include <limits>
#include <memory>

#include "body/grouping.hpp"
#include "data/dataset.hpp"
#include "metrics/lpips.hpp"
#include "model/inputs.hpp"
#include "model/transhuman.hpp"
#include "render/volume.hpp"

namespace th::pipeline {

// Token labels per frame (METHOD 2.5). A model that carries token groups (a loaded checkpoint)
// renders with those. A model without them (a run's start; a checkpoint written before
// checkpoints stored them; a reference import with model.grouping.kmeans_file "compute") gets
// them here from its model.grouping: a static grouping's labels are computed once and stored in
// the model, so every checkpoint written from it carries them. Fails when the stored labels do
// not label the body model's vertices.
class Tokens {
 public:
  Tokens(model::TransHumanImpl& model, const torch::Tensor& canonical);
  torch::Tensor labels(const data::FrameBody& body);

 private:
  std::unique_ptr<body::Grouping> grouping_;  // per-frame groupings only
  torch::Tensor canonical_, labels_;          // labels_: static groupings
};

// Sample -> FrameInputs on `device` (float32, except `canonical`, passed on in its own dtype:
// v_template in float64 gives the token positions of the reference [parity], METHOD 3.2).
model::FrameInputs frame_inputs(const data::Sample& sample, const torch::Tensor& canonical,
                                const torch::Tensor& labels, const torch::Device& device);

// The sample's rays for the renderer, on `device`.
render::Rays sample_rays(const data::Sample& sample, const torch::Device& device);

// Rendering policy, in one place: how a prepared frame's rays are rendered.
// Training: stratified samples, autograd on, the network in checkpointed chunks of
// render.train_chunk_points (render.train_recompute says which chunks keep their graphs), every
// sample evaluated, or with skip_far_points (train.skip_far_points) those within
// render.cull_distance of the body. Inference: no autograd, chunks of render.chunk_points,
// progressive rendering (culling, early ray termination) when render.progressive, every sample
// otherwise.
struct RenderPass {
  bool training = false;
  bool skip_far_points = false;  // training only
};
inline constexpr RenderPass kInference{false, false};

// The frame prepared for rendering with `render_config`: its culling distance (the body-distance
// structure, and readout windows at inference on CPU) is render.cull_distance.
model::FrameCache prepare_frame(model::TransHumanImpl& model, const model::FrameInputs& inputs,
                                const RenderConfig& render_config);

// The one render dispatcher: training, evaluation, sessions and benchmarks render through it.
render::RenderResult render(model::TransHumanImpl& model, const model::FrameCache& cache,
                            const render::Rays& rays, const RenderConfig& render_config,
                            const RenderPass& pass, render::Profile* profile = nullptr);

// The keep_graph_points of model::FrameField for render.train_recompute (auto, always, never).
int64_t keep_graph_points(const RenderConfig& config);

// prepare_frame + render.
struct Rendered {
  render::RenderResult result;
  model::FrameCache cache;
};
Rendered render_sample(model::TransHumanImpl& model, const RenderConfig& render_config,
                       const model::FrameInputs& inputs, const render::Rays& rays,
                       const RenderPass& pass, render::Profile* profile = nullptr);

// The last prepared frame, handed out again while the frame inputs stay the same value for value
// (several target views of one frame): the per-frame stages depend only on the inputs, so the
// views render exactly as if each prepared its own.
class FrameReuse {
 public:
  const model::FrameCache& prepare(model::TransHumanImpl& model, const model::FrameInputs& inputs,
                                   const RenderConfig& render_config);
  int64_t prepared() const { return prepared_; }
  int64_t reused() const { return reused_; }

 private:
  model::FrameInputs inputs_;
  model::FrameCache cache_;
  bool valid_ = false;
  int64_t prepared_ = 0, reused_ = 0;
};

// A test view rendered and scored with the protocol of METHOD 6: PSNR over the valid rays, SSIM
// and LPIPS (when `lpips` is given; NaN otherwise) on the crop to the valid-ray rectangle.
struct ViewResult {
  double psnr = 0, ssim = 0, lpips = std::numeric_limits<double>::quiet_NaN();
  double acc_max = 0;  // largest accumulated opacity (near 0 everywhere: a collapsed model)
  // Rays whose final transmittance 1 - acc is below 1e-3 and 1e-4 (opaque: early ray
  // termination pays only on those), of `rays` rendered.
  int64_t rays = 0, opaque_1e3 = 0, opaque_1e4 = 0;
  double seconds = 0;      // render time
  torch::Tensor pred, gt;  // (H, W, 3) float32 CPU, black outside the valid rays
  render::RenderStats stats;
};
// With `frames`, the frame is prepared through it (reused from the previous view when the
// inputs are the same); `seconds` then counts only what this view computed.
ViewResult evaluate_view(model::TransHumanImpl& model, const RenderConfig& render_config,
                         const data::Sample& sample, const model::FrameInputs& inputs,
                         metrics::LpipsImpl* lpips, const torch::Device& device,
                         FrameReuse* frames = nullptr);
// The scores of a view from its colours and accumulated opacity at the sample's valid rays,
// (R, 3) and (R) in the order of sample.ray_pixel, however they were rendered (exactly, or
// through a bake): what evaluate_view scores. `seconds` and `stats` are left 0.
ViewResult score_view(const torch::Tensor& ray_rgb, const torch::Tensor& ray_acc,
                      const data::Sample& sample, metrics::LpipsImpl* lpips,
                      const torch::Device& device);

// Fails unless every value of the network's output `rgb` is finite, naming `what` (the
// checkpoint and the view) and how many values are NaN or infinite: finite weights can still
// overflow, and such an output must not become a score or an image.
void require_finite_output(const torch::Tensor& rgb, const std::string& what);

// Scatters per-ray colours into an image (H, W, 3), black elsewhere.
torch::Tensor scatter_image(const torch::Tensor& rgb, const torch::Tensor& pixel, int64_t height,
                            int64_t width);

}  // namespace th::pipeline
