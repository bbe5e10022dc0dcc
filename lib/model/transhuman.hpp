#pragma once
// The TransHuman network (METHOD 3), defined in transhuman.cpp in the paper's order: what is
// computed once per frame (prepare: encoder, painting, TransHE's tokens and DPaRF's frames,
// METHOD 3.1-3.2) and what is computed per chunk of points (forward: DPaRF, FDI, the heads,
// METHOD 3.3-3.4). Each ablation of the ModelConfig is a plain branch there, or a module that the
// config leaves out. The exact shortcuts of METHOD 9 (folded weights, pixel readouts and their
// windows, the token table, the one-pass nearest-field query, the view-attention kernel) sit
// inside the operations the definition calls, each choosing its form by device, precision and
// grad mode (model/kernels/forms.hpp): on CPU the project's kernels, elsewhere LibTorch's.

#include <torch/torch.h>

#include <memory>
#include <string>
#include <vector>

#include "core/config.hpp"
#include "model/dparf.hpp"
#include "model/encoder.hpp"
#include "model/fdi.hpp"
#include "model/frame_cache.hpp"
#include "model/heads.hpp"
#include "model/inputs.hpp"
#include "model/precision.hpp"
#include "render/volume.hpp"

namespace th::model {

class TransHumanImpl : public torch::nn::Module {
 public:
  // Builds the modules.
  explicit TransHumanImpl(const ModelConfig& config);

  // The per-frame stages (model/frame_cache.hpp), in order: frame geometry and the body-distance
  // structure, encoder, folded weights, painting and the human representation, the pixel stage.
  // While autograd records, the tensors keep their history (training). `cull_distance` is the
  // renderer's culling distance (render.cull_distance; 0: none): the frame's body-distance
  // structure and the readout windows follow it.
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

  // Density and colour of points seen along K directions each (baking, METHOD 7.1): the trunk,
  // the pixel sampling and the colour head's product with e_v run once, the rest of the colour
  // head per direction. pts (N, 3) world, dirs (K, N, 3) any length -> sigma_raw (N) and rgb
  // logits (K, N, 3), equal to forward() with each direction. One chunk, as forward.
  struct DirectionalRaw {
    torch::Tensor sigma, rgb;
  };
  DirectionalRaw forward_directions(const FrameCache& cache, const torch::Tensor& pts,
                                    const torch::Tensor& dirs);

  // Per-stage wall times are added to `profile` when set (benchmarks; the stage names of
  // render::Profile: encoder, painting, transhe, readouts, dparf, sampling, fdi, heads); null:
  // none.
  void set_profile(render::Profile* profile) { profile_ = profile; }
  // The precision of the products (model/precision.hpp); fp32 through BLAS until set. The
  // parameters and the per-frame state stay fp32 either way.
  void set_products(const Products& products) { products_ = products; }
  const Products& products() const { return products_; }
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
  Trunk trunk(const FrameCache& frame, const torch::Tensor& pts);
  torch::Tensor density(const Trunk& t);
  torch::Tensor colour_readout(const FrameCache& frame, const Trunk& t);
  torch::Tensor colour(const FrameCache& frame, const Trunk& t, const torch::Tensor& readout,
                       const torch::Tensor& dirs);

  ModelConfig config_;
  TokenGroups token_groups_;
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
