#pragma once
// The network of METHOD 3 as one plain forward pass, in the paper's order: painting (3.1),
// TransHE (3.2), DPaRF (3.3), FDI and the heads (3.4). It is the definition that the fast
// plans of TransHumanImpl (model/plan.hpp: the exact shortcuts of METHOD 9, the CPU kernels)
// are tested against: plain LibTorch operations only, on any device and under autograd, with
// the model's own parameters (it creates none) and each ablation of ModelConfig an `if` where
// the paper's text varies it. It computes its positional encodings, cluster means, projections
// and view-direction code itself rather than with the helpers the model runs, so that a bug in
// one of those cannot pass on both sides of the equality tests.
//
// Everything is evaluated per call, the per-frame stages included (no FrameCache), in the
// parameters' floating-point type (fp32: the model's products are not consulted). BatchNorm
// normalises as the model's modules do (batch or running statistics) but never updates the
// running statistics; synchronised BatchNorm over several ranks is not part of it.

#include <torch/types.h>

#include <vector>

#include "model/inputs.hpp"
#include "model/transhuman.hpp"

namespace th::model {

struct NetworkOutput {
  torch::Tensor rgb;    // (N, 3) raw colour logits
  torch::Tensor sigma;  // (N) raw density sigma_raw
  // (N, 4) = [rgb, sigma], the layout of TransHumanImpl::forward.
  torch::Tensor raw() const;
};

// The frame `in` (reference views, cameras, body, token groups), pts: (N, 3) world points and
// dirs: (N, 3) their ray directions (any length) -> density and colour of every point.
NetworkOutput network_forward(const TransHumanImpl& model, const FrameInputs& in,
                              const torch::Tensor& pts, const torch::Tensor& dirs);

// The pieces of the plain pass that tests read on their own:
// p_v at full resolution: the ResNet levels (L0, L1, L2) upsampled to the images' size and the
// raw-RGB convolution, (V, 384, H, W) (256 channels w/o RGB).
torch::Tensor pixel_feature_map(const EncoderImpl& encoder,
                                const std::vector<torch::Tensor>& levels,
                                const torch::Tensor& images);
// grid_sample(bilinear, border, align_corners=true) of maps at pixel coordinates, with the
// reference's normalisation u * 2 / (W - 1) - 1. map: (V, C, H, W), uv: (N, V, 2) -> (N, V, C).
torch::Tensor grid_sample_pixels(const torch::Tensor& map, const torch::Tensor& uv);

}  // namespace th::model
