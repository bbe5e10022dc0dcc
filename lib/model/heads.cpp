#include "model/heads.hpp"

#include "model/positional_encoding.hpp"

namespace th::model {

namespace F = torch::nn::functional;

HeadsImpl::HeadsImpl(bool appearance, int64_t pixel_channels) : appearance_(appearance) {
  fc_3 = register_module("fc_3", torch::nn::Linear(256, 256));
  alpha_fc = register_module("alpha_fc", torch::nn::Linear(256, 1));
  feature_fc = register_module("feature_fc", torch::nn::Linear(256, 256));
  view_fc = register_module("view_fc", torch::nn::Linear(256 + kDirectionEncodingDim, 128));
  fc_4 = register_module("fc_4", torch::nn::Linear(128, 128));
  rgb_fc = register_module("rgb_fc", torch::nn::Linear(128, 3));
  if (appearance_) {
    rgb_res_0 = register_module("rgb_res_0", torch::nn::Linear(pixel_channels, 256));
    rgb_res_1 = register_module("rgb_res_1", torch::nn::Linear(pixel_channels, 128));
  }
}

torch::Tensor HeadsImpl::density(const torch::Tensor& e, const Products& P) {
  const auto h = P.linear(Products::fp32(e).mean(1), fc_3->weight, fc_3->bias).relu_();
  return P.linear_fp32(h, alpha_fc->weight, alpha_fc->bias).squeeze(1);
}

torch::Tensor HeadsImpl::color(const torch::Tensor& e, const torch::Tensor& p, const torch::Tensor& dir_code,
                               const Products& P) {
  auto c = Products::fp32(P.linear(e, feature_fc->weight, feature_fc->bias));
  if (appearance_) c = c + rgb_res_0(p);
  const auto d = dir_code.unsqueeze(1).expand({e.size(0), e.size(1), dir_code.size(1)});
  c = torch::relu(view_fc(torch::cat({c, d}, 2)));
  if (appearance_) c = c + rgb_res_1(p);
  return rgb_fc(torch::relu(fc_4(c.mean(1))));
}

torch::Tensor HeadsImpl::color_folded(const HeadsFolded& f, const torch::Tensor& e, const torch::Tensor& readout,
                                      const torch::Tensor& dir_code, const Products& P) {
  const auto wd = view_fc->weight.narrow(1, 256, kDirectionEncodingDim);
  // view_fc(cat(c, gamma)) = (view_fc_c . feature_fc) e + view_fc_c rgb_res_0(p) + view_fc_d gamma + b
  auto c = Products::fp32(P.linear(e, f.e_weight, f.e_bias)).add_(P.linear_fp32(dir_code, wd).unsqueeze(1));
  if (readout.defined()) c = c.add_(readout.narrow(2, 0, 128)).relu_() + readout.narrow(2, 128, 128);
  else c = c.relu_();
  return P.linear_fp32(P.linear_fp32(c.mean(1), fc_4->weight, fc_4->bias).relu_(), rgb_fc->weight, rgb_fc->bias);
}

}  // namespace th::model
