#pragma once
// The forms of the per-point network, chosen once when the model is built (TransHumanImpl's
// constructor calls the factories below, the only places that read the ablation and speed
// switches of ModelConfig). Each form makes its stage of the per-frame state
// (model/frame_cache.hpp) in prepare() and reads that stage per point; neither re-tests a
// config switch.
//
//   PixelForm    what points sample of the encoder output: nothing (w/o a), p_v materialised
//                (reference), p_v sampled from the levels (fast sampling), per-level readouts
//                (exact shortcuts), and at inference on CPU their window form.
//   NetworkForm  FDI and the heads with their own weights, or with folded weights (METHOD 9).
//   HumanRepresentation (model/human.hpp)  tokens (reference), token table (exact shortcut),
//                or the SPC baseline.

#include <torch/torch.h>

#include <memory>

#include "core/config.hpp"
#include "model/encoder.hpp"
#include "model/fdi.hpp"
#include "model/frame_cache.hpp"
#include "model/heads.hpp"
#include "model/precision.hpp"

namespace th::model {

// What a pixel form's prepare() may use of the frame.
struct PixelFrame {
  const EncodedViews& enc;
  const FrameGeometry& geometry;
  const torch::Tensor& vertices;  // (Nv, 3) world
  double cull_distance;           // 0: no culling (no readout windows)
};

class PixelForm {
 public:
  virtual ~PixelForm() = default;
  // The pixel stage of a frame. `folded` holds the colour head's folded readout where the
  // network form folds (exact shortcuts).
  virtual PixelStage prepare(const PixelFrame& frame, const NetworkStage& network) const = 0;
  // FDI's appearance input before its ReLU, alpha_res_0(p_v), at projections uv (N, V, 2)
  // -> (N, V, 256); undefined without the appearance branch.
  virtual torch::Tensor appearance(const PixelStage& stage, const torch::Tensor& uv) const = 0;
  // What the colour head reads of p_v at uv: p_v itself, or its folded readout (N, V, 256);
  // undefined without the appearance branch.
  virtual torch::Tensor colour(const PixelStage& stage, const torch::Tensor& uv) const = 0;
};

class NetworkForm {
 public:
  virtual ~NetworkForm() = default;
  virtual NetworkStage prepare() const = 0;
  // FDI: s, a (N, V, 256) (undefined when the branch is off) -> e (N, V, 256).
  virtual torch::Tensor trunk(const NetworkStage& stage, const torch::Tensor& s,
                              const torch::Tensor& a, const Products& products) const = 0;
  // The colour head: e, the pixel form's colour() output and gamma(d) (N, 27) -> rgb logits (N, 3).
  virtual torch::Tensor colour(const NetworkStage& stage, const torch::Tensor& e,
                               const torch::Tensor& pixels, const torch::Tensor& dir_code,
                               const Products& products) const = 0;
};

// The forms for a config (the modules are the model's own; the forms keep references to them).
std::unique_ptr<PixelForm> make_pixel_form(const ModelConfig& config, Encoder encoder, FDI fdi);
std::unique_ptr<NetworkForm> make_network_form(const ModelConfig& config, FDI fdi, Heads heads);

}  // namespace th::model
