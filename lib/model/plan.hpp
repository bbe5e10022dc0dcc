#pragma once
// How TransHumanImpl evaluates the network of METHOD 3 fast: the plan. The definition of the
// network is the plain pass (model/network.hpp); a plan computes the same function from a
// per-frame state (model/frame_cache.hpp) made once per frame, with the exact shortcuts of
// METHOD 9 where model.exact_shortcuts asks for them, the products in the precision it was built
// for, and the kernels of model/kernels/ where its tensors live on the CPU (their LibTorch forms
// elsewhere).
//
// A plan is built once for a precision (its Products), a device and a mode (training: autograd
// records; inference: it does not), and everything it decides is decided then: which form each
// stage of the frame takes and how its products run. TransHumanImpl keeps one plan per mode and
// picks it when it prepares a frame; the frame records the mode, and every chunk of points of
// that frame runs through the same plan. No stage of a plan tests a config switch, the device
// or the autograd mode again. The per-point stages read the frame state by its type
// (std::variant): the form a stage took at prepare() is the form its readers use.
//
// Profiling (benchmarks) wraps a plan (ProfiledPlan) and times its stages from outside.

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
  // The plan of `model` (whose modules it reads; it owns none) for `target`.
  Plan(TransHumanImpl& model, const PlanTarget& target);
  virtual ~Plan() = default;
  Plan(const Plan&) = delete;
  Plan& operator=(const Plan&) = delete;

  const PlanTarget& target() const { return target_; }
  // "readout windows", "pixel readouts" ...: the pixel stage this plan makes.
  const char* pixel_form() const;

  // ---- per frame (METHOD 3.1-3.3, 9), in the order prepare() runs them -----------------------
  // The ResNet levels of the reference images, fp32.
  virtual EncodedViews encode(const torch::Tensor& images) const;
  // The painted body: the holder features at the vertices' projections uv (V, Nv, 2).
  virtual torch::Tensor paint(const EncodedViews& enc, const torch::Tensor& uv,
                              const torch::Tensor& visibility) const;
  // TransHE and DPaRF's token frames (or the SPC volume), fp32.
  virtual HumanStage represent(const FrameInputs& in, const PaintedBody& body) const;
  // The per-point layers' weights: their own, or folded (METHOD 9).
  virtual NetworkStage weights() const;
  // What per-point sampling reads of the encoder output. `cull_distance` > 0 bounds the points
  // to the body's surroundings (the readout windows of the inference plan follow it).
  virtual PixelStage pixels(const EncodedViews& enc, const FrameGeometry& geometry,
                            const torch::Tensor& vertices, double cull_distance,
                            const NetworkStage& network) const;

  // ---- per point (METHOD 3.3, 3.4) -------------------------------------------------------------
  // s_v: the human representation at xs (N, 3) in the SMPL frame -> (N, V, 256) fp32.
  virtual torch::Tensor human(const FrameCache& frame, const torch::Tensor& xs) const;
  // a_v before its ReLU, alpha_res_0(p_v), at the projections uv (N, V, 2) -> (N, V, 256);
  // undefined without the appearance branch.
  virtual torch::Tensor appearance(const FrameCache& frame, const torch::Tensor& uv) const;
  // FDI: s_v, a_v (N, V, 256) (undefined where the branch is off) -> e_v (N, V, 256).
  virtual torch::Tensor fuse(const FrameCache& frame, const torch::Tensor& s,
                             const torch::Tensor& a) const;
  // The density head: e_v -> sigma_raw (N) fp32.
  virtual torch::Tensor density(const torch::Tensor& e) const;
  // What the colour head reads of p_v at uv: p_v, or its folded readout (N, V, 256); undefined
  // without the appearance branch.
  virtual torch::Tensor colour_pixels(const FrameCache& frame, const torch::Tensor& uv) const;
  // The colour head: e_v, colour_pixels(), gamma(d) (N, 27) -> rgb logits (N, 3) fp32.
  virtual torch::Tensor colour(const FrameCache& frame, const torch::Tensor& e,
                               const torch::Tensor& pixels, const torch::Tensor& dir_code) const;

 private:
  // The pixel stage's forms (see frame_cache.hpp), one chosen at construction.
  enum class PixelForm { none, map, levels, readouts, windows };

  torch::Tensor token_table_fields(const TokenTableStage& stage, const torch::Tensor& xs) const;
  torch::Tensor fuse_layers(const torch::Tensor& s, const torch::Tensor& a) const;
  torch::Tensor fuse_folded(const FDIFolded& f, const torch::Tensor& s,
                            const torch::Tensor& a) const;
  torch::Tensor colour_layers(const torch::Tensor& e, const torch::Tensor& p,
                              const torch::Tensor& dir_code) const;
  torch::Tensor colour_folded(const HeadsFolded& f, const torch::Tensor& e,
                              const torch::Tensor& readout, const torch::Tensor& dir_code) const;
  torch::Tensor read_windows(const WindowReadouts& px, const WindowReadout& readout,
                             const torch::Tensor& uv) const;
  // The products' layer y = x w^T + b in the compute type, and the same read back in fp32.
  torch::Tensor layer(const torch::nn::Linear& l, const torch::Tensor& x) const;
  torch::Tensor layer_fp32(const torch::nn::Linear& l, const torch::Tensor& x) const;

  TransHumanImpl& model_;
  PlanTarget target_;
  PixelForm pixel_form_ = PixelForm::none;
  bool folded_ = false;         // exact shortcuts: folded weights
  bool fast_painting_ = false;  // encoder.fast_sampling: painting sampled from the levels
};

// A plan whose stages add their wall time to `profile` (benchmarks): the stage names of
// render::Profile (encoder, painting, transhe, readouts, dparf, sampling, fdi, heads).
class ProfiledPlan final : public Plan {
 public:
  ProfiledPlan(TransHumanImpl& model, const PlanTarget& target, render::Profile* profile)
      : Plan(model, target), profile_(profile) {}

  EncodedViews encode(const torch::Tensor& images) const override;
  torch::Tensor paint(const EncodedViews& enc, const torch::Tensor& uv,
                      const torch::Tensor& visibility) const override;
  HumanStage represent(const FrameInputs& in, const PaintedBody& body) const override;
  PixelStage pixels(const EncodedViews& enc, const FrameGeometry& geometry,
                    const torch::Tensor& vertices, double cull_distance,
                    const NetworkStage& network) const override;
  torch::Tensor human(const FrameCache& frame, const torch::Tensor& xs) const override;
  torch::Tensor appearance(const FrameCache& frame, const torch::Tensor& uv) const override;
  torch::Tensor fuse(const FrameCache& frame, const torch::Tensor& s,
                     const torch::Tensor& a) const override;
  torch::Tensor density(const torch::Tensor& e) const override;
  torch::Tensor colour_pixels(const FrameCache& frame, const torch::Tensor& uv) const override;
  torch::Tensor colour(const FrameCache& frame, const torch::Tensor& e, const torch::Tensor& pixels,
                       const torch::Tensor& dir_code) const override;

 private:
  render::Profile* profile_;
};

}  // namespace th::model
