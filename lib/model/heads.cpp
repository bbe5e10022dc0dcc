#include "model/heads.hpp"

#include "model/positional_encoding.hpp"

namespace th::model {

HeadsImpl::HeadsImpl(bool appearance, int64_t pixel_channels) {
  fc_3 = register_module("fc_3", torch::nn::Linear(256, 256));
  alpha_fc = register_module("alpha_fc", torch::nn::Linear(256, 1));
  feature_fc = register_module("feature_fc", torch::nn::Linear(256, 256));
  view_fc = register_module("view_fc", torch::nn::Linear(256 + kDirectionEncodingDim, 128));
  fc_4 = register_module("fc_4", torch::nn::Linear(128, 128));
  rgb_fc = register_module("rgb_fc", torch::nn::Linear(128, 3));
  if (appearance) {
    rgb_res_0 = register_module("rgb_res_0", torch::nn::Linear(pixel_channels, 256));
    rgb_res_1 = register_module("rgb_res_1", torch::nn::Linear(pixel_channels, 128));
  }
}

HeadsFolded HeadsImpl::fold_plain() const {
  HeadsFolded f;
  const auto wc = view_fc->weight.narrow(1, 0, 256);
  f.e_weight = torch::mm(wc, feature_fc->weight);
  f.e_bias = torch::mv(wc, feature_fc->bias) + view_fc->bias;
  return f;
}

HeadsFolded HeadsImpl::fold_pixels() const {
  HeadsFolded f = fold_plain();
  const auto wc = view_fc->weight.narrow(1, 0, 256);
  f.readout_weight = torch::cat({torch::mm(wc, rgb_res_0->weight), rgb_res_1->weight}, 0);
  f.readout_bias = torch::cat({torch::mv(wc, rgb_res_0->bias), rgb_res_1->bias}, 0);
  return f;
}

}  // namespace th::model
