#pragma once
// The human representation branch h of METHOD 3 (selected by model.representation):
// - TokenFields: TransHE tokens (METHOD 3.2) read through DPaRF (METHOD 3.3) — the paper's model;
// - SPCTrilinear (spc.hpp): the NHP-style baseline of the ablations.
// Both end in fc_0 and return s_v = relu(fc_0(h_v)) per reference view. The form of each is
// fixed when it is built (make_human_representation).

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
  // The per-frame part: the painted body -> the human stage of the frame state.
  virtual HumanStage prepare(const FrameInputs& in, const PaintedBody& body) = 0;
  // The per-point part with the module's own layers. xs: (N, 3) points in the SMPL frame -> s:
  // (N, V, 256) fp32. `stage` is what prepare() made. (The token table of METHOD 9 is read by
  // the plan, model/plan.cpp, whose products apply fc_0's coordinate part.)
  virtual torch::Tensor forward(const HumanStage& stage, const torch::Tensor& xs) = 0;
};

// TransHE (tokens, transhe.hpp) + DPaRF (dparf.hpp) + fc_0 (reference names: ViT.*, fc_0.*),
// in the reference form: the Nk nearest tokens gathered and fc_0 applied per point (TokenStage).
class TokenFieldsImpl : public HumanRepresentation {
 public:
  explicit TokenFieldsImpl(const ModelConfig& config);

  HumanStage prepare(const FrameInputs& in, const PaintedBody& body) override;
  torch::Tensor forward(const HumanStage& stage, const torch::Tensor& xs) override;

  TransHE vit{nullptr};  // null: the "w/o TransHE" ablation
  torch::nn::Linear fc_0{nullptr};
  DPaRF dparf;

 protected:
  // The frame's tokens (TransHE over the painted body) and their DPaRF frames.
  FrameTokens tokens(const FrameInputs& in, const PaintedBody& body);

 private:
  TokenRecipe recipe_;
  int64_t nk_;
};

// The same network with METHOD 9's exact shortcut: fc_0's token part applied to the tokens once
// per frame (TokenTableStage); the plan reads it per point by a weighted gather of Nk rows.
class TokenTableImpl : public TokenFieldsImpl {
 public:
  using TokenFieldsImpl::TokenFieldsImpl;
  HumanStage prepare(const FrameInputs& in, const PaintedBody& body) override;
};

// Factory: the representation named by config.representation, in the form config.exact_shortcuts
// asks for.
std::shared_ptr<HumanRepresentation> make_human_representation(const ModelConfig& config);

}  // namespace th::model
