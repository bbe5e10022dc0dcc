#pragma once
// The composed TransHuman network (METHOD 3): encoder -> painting -> human representation
// (TransHE + DPaRF, or the SPC baseline) -> FDI -> heads. Per-frame work happens once in
// prepare(); forward() evaluates points. The components are chosen by the ModelConfig.

#include <torch/torch.h>

#include <memory>
#include <string>
#include <vector>

#include "core/config.hpp"
#include "model/encoder.hpp"
#include "model/fdi.hpp"
#include "model/frame_cache.hpp"
#include "model/heads.hpp"
#include "model/human.hpp"
#include "model/inputs.hpp"
#include "model/precision.hpp"
#include "render/progressive.hpp"
#include "render/volume.hpp"

namespace th::model {

class TransHumanImpl : public torch::nn::Module {
 public:
  explicit TransHumanImpl(const ModelConfig& config, double cull_distance = 0.1);

  // The per-frame stages (model/frame_cache.hpp), in order: frame geometry and the body-distance
  // structure, encoder, folded weights (exact shortcuts), painting and the human
  // representation, the pixel stage. Under autograd the tensors keep their history (training).
  FrameCache prepare(const FrameInputs& in);

  // pts: (N, 3) world, dirs: (N, 3) ray directions (any length) -> raw (N, 4): rgb logits,
  // sigma_raw. One chunk: the caller bounds N (see FrameField).
  torch::Tensor forward(const FrameCache& cache, const torch::Tensor& pts, const torch::Tensor& dirs);
  // As forward, but the colour branch runs only where sigma_raw > 0 (zeros elsewhere).
  torch::Tensor forward_density_first(const FrameCache& cache, const torch::Tensor& pts,
                                      const torch::Tensor& dirs);

  // Only the density sigma_raw (N) of points (N, 3) world: the colour branch is skipped (mesh
  // extraction). One chunk, as forward.
  torch::Tensor density(const FrameCache& cache, const torch::Tensor& pts);

  // Per-stage wall times are added to `profile` when set (benchmarks).
  void set_profile(render::Profile* profile) { profile_ = profile; }
  // The precision of the products (model/precision.hpp); fp32 through BLAS until set. The
  // parameters and the per-frame state stay fp32 either way.
  void set_products(const Products& products) { products_ = products; }
  const Products& products() const { return products_; }
  const ModelConfig& config() const { return config_; }

  Encoder encoder{nullptr};
  std::shared_ptr<HumanRepresentation> human;  // undefined for the "w/o h" ablation
  FDI fdi{nullptr};
  Heads heads{nullptr};

 private:
  // Per chunk of points, FDI's inputs: the human representation s_v (DPaRF, or SPC) and the
  // appearance a_v sampled at the points' projections uv (METHOD 3.3, 3.4).
  struct PointFeatures {
    torch::Tensor s, a;  // (N, V, 256) each; undefined when the branch is off (ablations)
    torch::Tensor uv;    // (N, V, 2) projections into the reference views
  };
  PointFeatures point_features(const FrameCache& cache, const torch::Tensor& pts);
  // FDI's output, the per-point trunk e_v, plus what the colour head needs.
  struct Trunk {
    torch::Tensor e, uv;  // e: (N, V, 256); uv: (N, V, 2)
  };
  Trunk trunk(const FrameCache& cache, const torch::Tensor& pts);
  torch::Tensor color(const FrameCache& cache, const Trunk& t, const torch::Tensor& dirs);
  // p_v at projections uv (N, V, 2) -> (N, V, Cpix), from the pixel stage's reference or
  // fast-sampling form.
  torch::Tensor pixel_features_at(const PixelStage& pixels, const torch::Tensor& uv);
  // A per-level readout (exact shortcuts) at uv -> (N, V, Cout).
  torch::Tensor readout_at(const PixelStage& pixels, const PixelReadout& readout, const torch::Tensor& uv);

  ModelConfig config_;
  double cull_distance_;
  Products products_;
  render::Profile* profile_ = nullptr;
};
TORCH_MODULE(TransHuman);

// The renderer's view of one prepared frame: chunks of at most `chunk_points` points. Under
// autograd with `checkpoint`, each call stores only its inputs and recomputes its chunks in the
// backward pass (memory bounded by one chunk); gradients reach the model parameters (.grad) and,
// through the cached frame tensors, the encoder and the transformer. The checkpointed path
// evaluates colour only where sigma_raw > 0 (same image, same gradients: zero weight there).
// Parameters used per point get their gradients during the backward pass through .grad, so use
// backward() (not torch::autograd::grad) on losses built from it.
// With `keep_graph_points` > 0, a call of at most that many points keeps its chunks' graphs from
// the forward pass instead (one forward less, memory of all its chunks); the backward pass
// runs the same chunks in the same order, so the gradients are the same bit for bit.
class FrameField : public render::RadianceField {
 public:
  FrameField(TransHumanImpl& model, const FrameCache& cache, int64_t chunk_points, bool checkpoint = true,
             int64_t keep_graph_points = 0);
  torch::Tensor raw(const torch::Tensor& pts, const torch::Tensor& dirs) override;
  torch::Tensor raw_density_first(const torch::Tensor& pts, const torch::Tensor& dirs) override;

 private:
  TransHumanImpl& model_;
  const FrameCache& cache_;
  int64_t chunk_;
  bool checkpoint_;
  int64_t keep_graph_points_;
};

// render.train_recompute "auto": training field calls of up to this many points keep their
// chunks' graphs (the demo's 16,384 samples per step; about 60 MiB of graph per 1,000 points).
constexpr int64_t kKeepGraphPoints = 65536;
// The keep_graph_points of FrameField for render.train_recompute (auto, always, never).
int64_t keep_graph_points(const RenderConfig& config);

// Rendering one prepared frame the way training and inference do it.
// Training: stratified samples; every sample evaluated (or, with skip_far_points, those within
// render.cull_distance of the body) in chunks of render.train_chunk_points, recomputed in the
// backward pass; one field call for all rays so per-frame gradient buffers are made once.
// rays: (R) rays of the target view -> rgb (R, 3) etc. with autograd history.
render::RenderResult render_training_rays(TransHumanImpl& model, const FrameCache& cache,
                                          const render::Rays& rays, const RenderConfig& config,
                                          bool skip_far_points = false, render::Profile* profile = nullptr);
// Inference: no stratification; progressive rendering (render.progressive) or every sample;
// chunks of render.chunk_points; no autograd.
render::RenderResult render_rays(TransHumanImpl& model, const FrameCache& cache, const render::Rays& rays,
                                 const RenderConfig& config, render::Profile* profile = nullptr);

// Active parameters per module (METHOD 3.4): encoder (ResNet-18 to layer2), reduction + colour,
// ViT (or the SPC network), heads (fc_0, FDI and heads), and "total" last.
struct ParameterCount {
  std::string module;
  int64_t count = 0;
};
std::vector<ParameterCount> parameter_counts(const TransHumanImpl& model);

}  // namespace th::model
