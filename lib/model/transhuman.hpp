#pragma once
// The composed TransHuman network (METHOD 3): encoder -> painting -> human representation
// (TransHE + DPaRF, or the SPC baseline) -> FDI -> heads. Per-frame work happens once in
// prepare(); forward() evaluates points. The components and their forms are chosen by the
// ModelConfig when the model is built; how they run (precision, forms, kernels) is the plan's
// (model/plan.hpp), built once per mode and device.

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
#include "model/plan.hpp"
#include "model/precision.hpp"
#include "render/volume.hpp"

namespace th::model {

class TransHumanImpl : public torch::nn::Module {
 public:
  // Builds the modules.
  explicit TransHumanImpl(const ModelConfig& config);

  // The per-frame stages (model/frame_cache.hpp), in order: frame geometry and the body-distance
  // structure, encoder, folded weights, painting and the human
  // representation, the pixel stage, made by the plan of the current mode: the training plan
  // while autograd records (the tensors keep their history), the inference plan otherwise.
  // `cull_distance` is the renderer's culling distance (render.cull_distance; 0: none): the
  // frame's body-distance structure and the readout windows follow it.
  FrameCache prepare(const FrameInputs& in, double cull_distance);

  // pts: (N, 3) world, dirs: (N, 3) ray directions (any length) -> raw (N, 4): rgb logits,
  // sigma_raw. One chunk: the caller bounds N (see FrameField).
  torch::Tensor forward(const FrameCache& cache, const torch::Tensor& pts,
                        const torch::Tensor& dirs);
  // As forward, but the colour branch runs only where sigma_raw > 0 (zeros elsewhere).
  torch::Tensor forward_density_first(const FrameCache& cache, const torch::Tensor& pts,
                                      const torch::Tensor& dirs);

  // Only the density sigma_raw (N) of points (N, 3) world: the colour branch is skipped (mesh
  // extraction). One chunk, as forward.
  torch::Tensor density(const FrameCache& cache, const torch::Tensor& pts);

  // Density and colour of points seen along K directions (baking, METHOD 7.1): the trunk and the
  // pixel sampling run once, the colour head once per direction. pts: (N, 3) world, directions:
  // (K, 3) any length -> sigma_raw (N) and rgb logits (K, N, 3); equal to forward() with each
  // direction. One chunk, as forward.
  struct DirectionalRaw {
    torch::Tensor sigma, rgb;
  };
  DirectionalRaw forward_directions(const FrameCache& cache, const torch::Tensor& pts,
                                    const torch::Tensor& directions);

  // Per-stage wall times are added to `profile` when set (benchmarks); null: none. The plans are
  // built again.
  void set_profile(render::Profile* profile);
  // The precision of the products (model/precision.hpp); fp32 through BLAS until set. The
  // parameters and the per-frame state stay fp32 either way. The plans are built again.
  void set_products(const Products& products);
  const Products& products() const { return products_; }
  // The plan of a mode (training: autograd records) on `device`, built on first use and kept
  // until the products, the profile or the device change.
  const Plan& plan(bool training, const torch::Device& device);
  const ModelConfig& config() const { return config_; }
  // The token groups of the weights (model/inputs.hpp): set when a checkpoint is loaded or when a
  // run computes them at its start; empty before either.
  const TokenGroups& token_groups() const { return token_groups_; }
  void set_token_groups(TokenGroups groups) { token_groups_ = std::move(groups); }

  Encoder encoder{nullptr};
  std::shared_ptr<HumanRepresentation> human;  // undefined for the "w/o h" ablation
  FDI fdi{nullptr};
  Heads heads{nullptr};

 private:
  // FDI's output, the per-point trunk e_v, plus the projections uv (N, V, 2) that the colour
  // head samples again.
  struct Trunk {
    torch::Tensor e, uv;
  };
  Trunk trunk(const Plan& plan, const FrameCache& cache, const torch::Tensor& pts);
  torch::Tensor color(const Plan& plan, const FrameCache& cache, const Trunk& t,
                      const torch::Tensor& dirs);
  // The plan that prepared `cache`.
  const Plan& plan_of(const FrameCache& cache);

  ModelConfig config_;
  TokenGroups token_groups_;
  Products products_;
  render::Profile* profile_ = nullptr;
  std::shared_ptr<const Plan> plans_[2];  // [inference, training]
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
  FrameField(TransHumanImpl& model, const FrameCache& cache, int64_t chunk_points,
             bool checkpoint = true, int64_t keep_graph_points = 0);
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
// chunks' graphs (the demo's 16,384 samples per step; the memory it costs: docs/PERFORMANCE.md).
constexpr int64_t kKeepGraphPoints = 65536;

// Active parameters per module (METHOD 3.4): encoder (ResNet-18 to layer2), reduction + colour,
// ViT (or the SPC network), heads (fc_0, FDI and heads), and "total" last.
struct ParameterCount {
  std::string module;
  int64_t count = 0;
};
std::vector<ParameterCount> parameter_counts(const TransHumanImpl& model);

}  // namespace th::model
