#pragma once
// The "SPC + trilinear" baseline of the ablations (NHP-style human representation): the
// painted vertex features of each view are embedded, averaged into the voxels of a coarse grid
// over the frame's posed body (SMPL frame), diffused by dense 3D convolutions (instead of NHP's
// sparse ones) and read at the query point by trilinear interpolation. Ends in fc_0 like the
// token representation.

#include "model/dparf.hpp"

namespace th::model {

class SPCTrilinearImpl : public HumanRepresentation {
 public:
  explicit SPCTrilinearImpl(const ModelConfig& config);

  HumanStage prepare(const FrameInputs& in, const PaintedBody& body) override;
  torch::Tensor forward(const HumanStage& stage, const torch::Tensor& xs,
                        const Products& products) override;

  torch::nn::Linear embed{nullptr}, fc_0{nullptr};
  torch::nn::Sequential conv{nullptr};

 private:
  SPCConfig config_;
};

}  // namespace th::model
