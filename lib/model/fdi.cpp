#include "model/fdi.hpp"

namespace th::model {

FDIImpl::FDIImpl(const FDIConfig& config, int64_t pixel_channels) {
  if (config.appearance) {
    alpha_res_0 = register_module("alpha_res_0", torch::nn::Linear(pixel_channels, 256));
    key0 = register_module("key0", torch::nn::Linear(256, 128));
    value0 = register_module("value0", torch::nn::Linear(256, 256));
  }
  if (config.human) {
    key1 = register_module("key1", torch::nn::Linear(256, 128));
    value1 = register_module("value1", torch::nn::Linear(256, 256));
  }
  fc_1 = register_module("fc_1", torch::nn::Linear(256, 256));
  fc_2 = register_module("fc_2", torch::nn::Linear(256, 256));
}

// fc_1 is linear: folded into both value projections; each key projection shares one product
// with its value projection. fc_1's bias joins the query side where there is one (the attention
// weights multiply the value side).

FDIFolded FDIImpl::fold() const {
  return key0 && key1 ? fold_cross() : key0 ? fold_self() : fold_human_only();
}

FDIFolded FDIImpl::fold_cross() const {
  const auto& W1 = fc_1->weight;
  FDIFolded f;
  f.w0 = torch::cat({key0->weight, torch::mm(W1, value0->weight)}, 0);
  f.b0 = torch::cat({key0->bias, torch::mv(W1, value0->bias)}, 0);
  f.w1 = torch::cat({key1->weight, torch::mm(W1, value1->weight)}, 0);
  f.b1 = torch::cat({key1->bias, torch::mv(W1, value1->bias) + fc_1->bias}, 0);
  return f;
}

FDIFolded FDIImpl::fold_self() const {
  const auto& W1 = fc_1->weight;
  FDIFolded f;
  f.w0 = torch::cat({key0->weight, torch::mm(W1, value0->weight)}, 0);
  f.b0 = torch::cat({key0->bias, torch::mv(W1, value0->bias)}, 0);
  return f;
}

FDIFolded FDIImpl::fold_human_only() const {
  const auto& W1 = fc_1->weight;
  FDIFolded f;
  f.w1 = torch::mm(W1, value1->weight);
  f.b1 = torch::mv(W1, value1->bias) + fc_1->bias;
  return f;
}

}  // namespace th::model
