#pragma once
// How TransHumanImpl evaluates the network of METHOD 3: the plan. The definition of the
// network is the plain pass (model/network.hpp); a plan computes the same function from a
// per-frame state (model/frame_cache.hpp) made once per frame, with the exact shortcuts of
// METHOD 9, the products in the precision it was built for, and the kernels of model/kernels/
// where its tensors live on the CPU (their LibTorch forms elsewhere).
//
// A plan is built once for a precision (its Products), a device and a mode (training: autograd
// records; inference: it does not), and everything it decides is decided then: where the pixel
// stage takes its window form (inference with the CPU kernels) and how its products run.
// TransHumanImpl keeps one plan per mode and picks it when it prepares a frame; the frame records
// the mode, and every chunk of points of that frame runs through the same plan. The per-point
// stages read the frame state by its type (std::variant): the form a stage took at prepare() is
// the form its readers use.
//
// Each stage adds its wall time to the plan's profile when one is set (benchmarks): the stage
// names of render::Profile (encoder, painting, transhe, readouts, dparf, sampling, fdi, heads).

#include <torch/torch.h>

#include <memory>

#include "core/config.hpp"
#include "model/frame_cache.hpp"
#include "model/inputs.hpp"
#include "model/precision.hpp"

namespace th::render {
struct Profile;
}

namespace th::model {

class TransHumanImpl;

// What a plan is built for.
struct PlanTarget {
  Products products;                   // the precision of the per-point products
  torch::Device device = torch::kCPU;  // where the frame's tensors live
  bool training = false;               // autograd records (training) or not (inference)
  // The CPU kernels of model/kernels/ or their LibTorch forms (model/kernels/forms.hpp).
  bool cpu_kernels = true;
};

class Plan {
 public:
  // The plan of `model` (whose modules it reads; it owns none) for `target`; stage times go to
  // `profile` when it is not null.
  Plan(TransHumanImpl& model, const PlanTarget& target, render::Profile* profile = nullptr);
  Plan(const Plan&) = delete;
  Plan& operator=(const Plan&) = delete;

  const PlanTarget& target() const { return target_; }
  // "readout windows", "pixel readouts" or "no pixels": the pixel stage this plan makes.
  const char* pixel_form() const;

  // ---- per frame (METHOD 3.1-3.3, 9), in the order prepare() runs them -----------------------
  // The ResNet levels of the reference images, fp32.
  EncodedViews encode(const torch::Tensor& images) const;
  // The painted body: the holder features at the vertices' projections uv (V, Nv, 2).
  torch::Tensor paint(const EncodedViews& enc, const torch::Tensor& uv,
                      const torch::Tensor& visibility) const;
  // TransHE and DPaRF's token frames with fc_0's token table (or the SPC volume), fp32.
  HumanStage represent(const FrameInputs& in, const PaintedBody& body) const;
  // The per-point layers' weights, folded (METHOD 9).
  FoldedWeights weights() const;
  // What per-point sampling reads of the encoder output. `cull_distance` > 0 bounds the points
  // to the body's surroundings (the readout windows of the inference plan follow it).
  PixelStage pixels(const EncodedViews& enc, const FrameGeometry& geometry,
                    const torch::Tensor& vertices, double cull_distance,
                    const FoldedWeights& network) const;

  // ---- per point (METHOD 3.3, 3.4) -------------------------------------------------------------
  // s_v: the human representation at xs (N, 3) in the SMPL frame -> (N, V, 256) fp32.
  torch::Tensor human(const FrameCache& frame, const torch::Tensor& xs) const;
  // a_v before its ReLU, alpha_res_0(p_v), at the projections uv (N, V, 2) -> (N, V, 256);
  // undefined without the appearance branch.
  torch::Tensor appearance(const FrameCache& frame, const torch::Tensor& uv) const;
  // FDI: s_v, a_v (N, V, 256) (undefined where the branch is off) -> e_v (N, V, 256).
  torch::Tensor fuse(const FrameCache& frame, const torch::Tensor& s, const torch::Tensor& a) const;
  // The density head: e_v -> sigma_raw (N) fp32.
  torch::Tensor density(const torch::Tensor& e) const;
  // What the colour head reads of p_v at uv: its folded readout (N, V, 256); undefined without
  // the appearance branch.
  torch::Tensor colour_pixels(const FrameCache& frame, const torch::Tensor& uv) const;
  // The colour head: e_v, colour_pixels(), gamma(d) (N, 27) -> rgb logits (N, 3) fp32.
  torch::Tensor colour(const FrameCache& frame, const torch::Tensor& e, const torch::Tensor& pixels,
                       const torch::Tensor& dir_code) const;

 private:
  // The pixel stage's forms (see frame_cache.hpp), one chosen at construction.
  enum class PixelForm { none, readouts, windows };

  // The pixel stage's `pick` readout (alpha or colour) at uv (N, V, 2), in the stage's form.
  template <class Pick>
  torch::Tensor read_pixels(const PixelStage& stage, const torch::Tensor& uv, Pick pick) const;
  torch::Tensor read_windows(const WindowReadouts& px, const WindowReadout& readout,
                             const torch::Tensor& uv) const;

  TransHumanImpl& model_;
  PlanTarget target_;
  render::Profile* profile_;
  PixelForm pixel_form_ = PixelForm::none;
};

}  // namespace th::model
