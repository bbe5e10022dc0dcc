#pragma once
// The per-frame state of the network, one typed struct per stage, in the paper's order
// (METHOD 3): frame geometry -> encoder (pixel features) -> TransHE (tokens) -> DPaRF's token
// frames -> folded FDI/head weights. TransHumanImpl::prepare makes it once per frame; every
// chunk of points reads it. Under autograd the tensors keep their history back to the encoder,
// the transformer and the layer weights (training).
//
// A stage that varies holds one of its forms (std::variant): the ablation's (no pixels, no
// human branch, the SPC baseline) or, for the pixel stage, the one that suits where it runs
// (readout windows for inference on CPU, model/pixels.hpp). Each form lists its tensors in `visit`;
// a test walks the autograd graph of the per-point network and fails when it reaches per-frame work
// through a tensor that no stage visits (tests/model/test_frame_cache.cpp). Parameters that a stage
// merely refers to are leaves already and are not visited.

#include <torch/types.h>

#include <functional>
#include <memory>
#include <variant>
#include <vector>

#include "model/encoder.hpp"
#include "model/fdi.hpp"
#include "model/heads.hpp"
#include "render/body_distance.hpp"

namespace th::model {

// The reference cameras and the body's placement (from FrameInputs).
struct FrameGeometry {
  torch::Tensor K, R, T;  // (V, 3, 3), (V, 3, 3), (V, 3, 1) reference cameras
  torch::Tensor Rh, Th;   // (3, 3), (3): x_smpl = (x_world - Th) Rh
  // Distance to the body for culling (METHOD 4, 9); null when prepared without a culling distance.
  std::shared_ptr<const render::BodyDistance> body;
  void visit(const TensorVisitor& fn);
};

// DPaRF's token frames (METHOD 3.3): each token's origin Oc (the cluster mean of the posed
// vertices in the SMPL frame) and axes Rc (the cluster mean of the blended rotations A, not
// re-orthonormalised [parity]).
struct TokenFrames {
  torch::Tensor origins;    // (Nt, 3) Oc, SMPL frame
  torch::Tensor rotations;  // (Nt, 3, 3) Rc
};

// The painted body (METHOD 3.1): the reference views' holder features at the body's vertices,
// input of the human representation; not kept past prepare().
struct PaintedBody {
  torch::Tensor features;     // (V, Nv, C), zero where the vertex is invisible in a view
  torch::Tensor xs_vertices;  // (Nv, 3) posed vertices in the SMPL frame
};

// ---- pixel stage: what per-point sampling reads of the encoder output (METHOD 3.1, 9) -------

// "w/o a" ablation: nothing is read.
struct NoPixels {
  void visit(const TensorVisitor&) {}
};
// The linear layers that read p_v applied once per ResNet level (METHOD 9), for the appearance
// feature (FDI's alpha_res_0) and for the colour head (folded readout); p_v is never formed.
struct PixelReadouts {
  PixelGeometry geometry;
  PixelReadout alpha, color;
  void visit(const TensorVisitor& fn);
};
// Readout windows (inference on CPU, model/pixels.hpp): the readouts at full resolution on a
// rectangle of each view around the body; the encoder's levels serve the points outside them.
struct WindowReadouts {
  EncodedViews enc;
  PixelWindows windows;
  WindowReadout alpha, color;
  void visit(const TensorVisitor& fn);
};
using PixelStage = std::variant<NoPixels, PixelReadouts, WindowReadouts>;

// ---- human stage: read by DPaRF (METHOD 3.2, 3.3), or the SPC baseline's volume --------------

// "w/o h" ablation.
struct NoHuman {
  void visit(const TensorVisitor&) {}
};
// The token frames, and fc_0's token part applied to the tokens T_v once, (Nt, V * 256)
// (METHOD 9).
struct TokenTableStage {
  TokenFrames frames;
  torch::Tensor table;
  torch::Tensor table_grad_sink;  // see weighted_gather (chunked recomputation)
  void visit(const TensorVisitor& fn);
};
// SPC baseline: the convolved feature volume, its corner and extent in the SMPL frame.
struct SPCStage {
  torch::Tensor grid, lo, extent;
  void visit(const TensorVisitor& fn);
};
using HumanStage = std::variant<NoHuman, TokenTableStage, SPCStage>;

// ---- network stage: the per-point layers' weights, folded (METHOD 9) -------------------------

// FDI's and the colour head's products, folded once per frame.
struct FoldedWeights {
  FDIFolded fdi;
  HeadsFolded heads;
  void visit(const TensorVisitor& fn);
};

struct FrameCache {
  FrameGeometry geometry;
  PixelStage pixels;
  HumanStage human;
  FoldedWeights network;

  // Every tensor of the state, visited in a fixed order, with its gradient-sink slot where the
  // tensor is a table read by weighted_gather (null otherwise). The checkpointed recomputation
  // swaps the tensors that require a gradient for leaves; memory accounting sums them.
  void visit(const TensorVisitor& fn);
  // Bytes held by the defined tensors (shared tensors counted once).
  double nbytes() const;
};

}  // namespace th::model
