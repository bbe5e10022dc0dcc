#pragma once
// Everything the per-point network needs about one frame, computed once by
// TransHuman::prepare: named tensors (some carry autograd history back to the encoder, ViT and
// layer weights) plus plain geometry.

#include <torch/types.h>

#include <map>
#include <memory>
#include <string>

#include "model/encoder.hpp"
#include "render/body_distance.hpp"

namespace th::model {

struct FrameCache {
  std::map<std::string, torch::Tensor> tensors;
  PixelGeometry geometry;                              // reference views and feature levels
  std::shared_ptr<const render::BodyDistance> body;   // distance culling (SPEC 4, 9)
  // Gradient buffers of gathered tables during chunked recomputation (see weighted_gather).
  std::map<std::string, torch::Tensor> grad_sinks;

  const torch::Tensor& at(const std::string& name) const {
    const auto it = tensors.find(name);
    TORCH_CHECK(it != tensors.end(), "frame cache has no tensor '", name, "'");
    return it->second;
  }
  bool has(const std::string& name) const { return tensors.count(name) > 0; }
  torch::Tensor sink(const std::string& name) const {
    const auto it = grad_sinks.find(name);
    return it == grad_sinks.end() ? torch::Tensor() : it->second;
  }
  // Tables read by weighted_gather, which can take a gradient sink.
  static bool gathered(const std::string& name) {
    return name == "human.table" || name == "app.alpha.table" || name == "app.color.table";
  }
};

}  // namespace th::model
