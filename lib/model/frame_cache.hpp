#pragma once
// The per-frame state of the network, one typed struct per stage, in the paper's order
// (METHOD 3): frame geometry -> encoder (pixel features) -> TransHE (tokens) -> DPaRF's token
// frames -> folded FDI/head weights. TransHumanImpl::prepare makes it once per frame; every
// chunk of points reads it. Under autograd the tensors keep their history back to the encoder,
// the transformer and the layer weights (training).
//
// Each stage has a reference form and, with model.exact_shortcuts, the form METHOD 9's exact
// shortcuts give it (model/shortcuts.hpp makes those; a field is undefined when its form is
// not in use).

#include <torch/types.h>

#include <functional>
#include <memory>
#include <vector>

#include "model/dparf.hpp"
#include "model/encoder.hpp"
#include "model/fdi.hpp"
#include "model/heads.hpp"
#include "render/body_distance.hpp"

namespace th::model {

// The reference cameras and the body's placement (from FrameInputs).
struct FrameGeometry {
  torch::Tensor K, R, T;  // (V, 3, 3), (V, 3, 3), (V, 3, 1) reference cameras
  torch::Tensor Rh, Th;   // (3, 3), (3): x_smpl = (x_world - Th) Rh
  std::shared_ptr<const render::BodyDistance> body;  // distance culling (METHOD 4, 9)
};

// The painted body (METHOD 3.1): the reference views' holder features at the body's vertices,
// input of the human representation; not kept past prepare().
struct PaintedBody {
  torch::Tensor features;     // (V, Nv, 192), zero where the vertex is invisible in a view
  torch::Tensor xs_vertices;  // (Nv, 3) posed vertices in the SMPL frame
};

// The encoder stage as per-point sampling reads it (METHOD 3.1): p_v at the projections.
struct PixelStage {
  PixelGeometry geometry;  // views, image size and level sizes
  // Reference form: p_v materialised, (V, Cpix, H, W) (encoder.fast_sampling false).
  torch::Tensor pixel;
  // Fast sampling: the ResNet levels and the images; p_v sampled exactly from them.
  std::vector<torch::Tensor> levels;
  torch::Tensor images;
  // Exact shortcuts: the linear layers that read p_v applied once per level (METHOD 9), for the
  // appearance feature (FDI's alpha_res_0) and for the colour head (folded readout).
  PixelReadout alpha, color;
  // Readout windows (inference, METHOD 9, model/shortcuts.hpp): where the readouts' window
  // tables lie; levels and images above then serve the points outside them.
  PixelWindows windows;
};

// The human representation stage read by DPaRF (METHOD 3.2, 3.3), or the SPC baseline's volume.
struct HumanStage {
  TokenFrames frames;  // token frames (origins, rotations) of the non-empty tokens
  // Reference form: the tokens T_v after TransHE, (V, Nt, C).
  torch::Tensor tokens;
  // Exact shortcut: fc_0's token part applied to the tokens, (Nt, V * 256) (METHOD 9).
  torch::Tensor table;
  torch::Tensor table_grad_sink;  // see weighted_gather (chunked recomputation)
  // SPC baseline: the convolved feature volume, its corner and extent in the SMPL frame.
  torch::Tensor grid, lo, extent;
};

// Folded layer weights (METHOD 9), once per frame: FDI's and the colour head's products.
struct FoldedWeights {
  FDIFolded fdi;
  HeadsFolded heads;
};

struct FrameCache {
  FrameGeometry geometry;
  PixelStage pixels;
  HumanStage human;
  FoldedWeights folded;

  // Every tensor of the state, visited in a fixed order, with its gradient-sink slot where the
  // tensor is a table read by weighted_gather (null otherwise). The checkpointed recomputation
  // swaps the tensors that require a gradient for leaves; memory accounting sums them.
  void visit(const std::function<void(torch::Tensor& tensor, torch::Tensor* grad_sink)>& fn);
  // Bytes held by the defined tensors (shared tensors counted once).
  double nbytes() const;
};

}  // namespace th::model
