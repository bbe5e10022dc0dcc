#pragma once
// The human representation branch h of SPEC 3 (selected by model.representation):
// - TokenFields: TransHE tokens (SPEC 3.2) read through DPaRF (SPEC 3.3) — the paper's model;
// - SPCTrilinear (spc.hpp): the NHP-style baseline of the ablations.
// Both end in fc_0 and return s_v = relu(fc_0(h_v)) per reference view.

#include <torch/torch.h>

#include <memory>

#include "core/config.hpp"
#include "model/dparf.hpp"
#include "model/frame_cache.hpp"
#include "model/inputs.hpp"
#include "model/transhe.hpp"

namespace th::model {

class HumanRepresentation : public torch::nn::Module {
 public:
  // painted: (V, Nv, 192) painted body (SPEC 3.1); xs_vertices: (Nv, 3) posed vertices in
  // the SMPL frame. Stores the per-frame tensors in cache.tensors under "human.*".
  virtual void prepare(const FrameInputs& in, const torch::Tensor& painted,
                       const torch::Tensor& xs_vertices, FrameCache& cache) = 0;
  // xs: (N, 3) points in the SMPL frame -> s: (N, V, 256).
  virtual torch::Tensor forward(const FrameCache& cache, const torch::Tensor& xs) = 0;
};

// TransHE + DPaRF + fc_0 (reference names: ViT.*, fc_0.*).
class TokenFieldsImpl : public HumanRepresentation {
 public:
  explicit TokenFieldsImpl(const ModelConfig& config);

  void prepare(const FrameInputs& in, const torch::Tensor& painted, const torch::Tensor& xs_vertices,
               FrameCache& cache) override;
  torch::Tensor forward(const FrameCache& cache, const torch::Tensor& xs) override;

  // The tokens T_v after the transformer: (V, Nt, 192), and the token positions fed to the PE
  // (normalised, (Nt, 3)), for one frame. Empty clusters are dropped.
  struct Tokens {
    torch::Tensor features, positions, keep;
    TokenFrames frames;
  };
  Tokens tokens(const FrameInputs& in, const torch::Tensor& painted, const torch::Tensor& xs_vertices);

  TransHE vit{nullptr};
  torch::nn::Linear fc_0{nullptr};
  DPaRF dparf;

 private:
  ModelConfig config_;
};
TORCH_MODULE(TokenFields);

// Factory: the representation named by config.representation.
std::shared_ptr<HumanRepresentation> make_human_representation(const ModelConfig& config);

}  // namespace th::model
