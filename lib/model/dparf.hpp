#pragma once
// DPaRF (METHOD 3.3) and the human representation branch h it belongs to (selected by
// model.representation):
// - TokenFields: TransHE tokens (METHOD 3.2, transhe.hpp) read through DPaRF: the paper's model;
// - SPCTrilinear (spc.hpp): the NHP-style baseline of the ablations.
// Both end in fc_0 and return s_v = relu(fc_0(h_v)) per reference view.

#include <torch/torch.h>

#include <memory>

#include "core/config.hpp"
#include "model/frame_cache.hpp"
#include "model/inputs.hpp"
#include "model/precision.hpp"
#include "model/transhe.hpp"

namespace th::model {

class HumanRepresentation : public torch::nn::Module {
 public:
  // The per-frame part: the painted body -> the human stage of the frame state.
  virtual HumanStage prepare(const FrameInputs& in, const PaintedBody& body) = 0;
  // The per-point part. xs: (N, 3) points in the SMPL frame -> s: (N, V, 256), fp32 or the type
  // products.between(fp32) names (only products read s). `stage` is what prepare() made;
  // `products` run the per-point products.
  virtual torch::Tensor forward(const HumanStage& stage, const torch::Tensor& xs,
                                const Products& products) = 0;
};

// TransHE (tokens, transhe.hpp) + DPaRF (METHOD 3.3) + fc_0 (reference names: ViT.*, fc_0.*).
// DPaRF: each token owns a local frame (origin Oc, axes Rc: frame_cache.hpp's TokenFrames); a
// point reads its Nk nearest fields weighted by softmax(-distance / T), h_v = sum_k w_k [T_v(k),
// g_k] with g_k the encoded local coordinates Rc(k)^T (xs - Oc(k)) (or the point's own, or none),
// and s_v = relu(fc_0(h_v)). With METHOD 9's exact shortcut: fc_0 is linear and the weights sum
// to 1, so fc_0's token part is applied to the Nt tokens once per frame (the token table) and read
// per point by a weighted gather of the Nk nearest rows, plus fc_0 of sum_k w_k g_k.
class TokenFieldsImpl : public HumanRepresentation {
 public:
  explicit TokenFieldsImpl(const ModelConfig& config);

  HumanStage prepare(const FrameInputs& in, const PaintedBody& body) override;
  torch::Tensor forward(const HumanStage& stage, const torch::Tensor& xs,
                        const Products& products) override;

  // Width of g_k: 63 for relative/absolute coordinates (10 frequencies), 0 for none.
  int64_t coord_dim() const;

  TransHE vit{nullptr};  // null: the "w/o TransHE" ablation
  torch::nn::Linear fc_0{nullptr};

 private:
  ModelConfig config_;
};

// Factory: the representation named by config.representation.
std::shared_ptr<HumanRepresentation> make_human_representation(const ModelConfig& config);

}  // namespace th::model
