#include "model/heads.hpp"

#include "model/positional_encoding.hpp"

namespace th::model {

namespace F = torch::nn::functional;

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

torch::Tensor HeadsImpl::density(const torch::Tensor& e, const Products& P) {
  const auto h = P.linear(Products::fp32(e).mean(1), fc_3->weight, fc_3->bias).relu_();
  return P.linear_fp32(h, alpha_fc->weight, alpha_fc->bias).squeeze(1);
}

// ---- reference
// -----------------------------------------------------------------------------------

torch::Tensor HeadsImpl::color_pixels(const torch::Tensor& e, const torch::Tensor& p,
                                      const torch::Tensor& dir_code, const Products& P) {
  auto c = Products::fp32(P.linear(e, feature_fc->weight, feature_fc->bias)) + rgb_res_0(p);
  const auto d = dir_code.unsqueeze(1).expand({e.size(0), e.size(1), dir_code.size(1)});
  c = torch::relu(view_fc(torch::cat({c, d}, 2))) + rgb_res_1(p);
  return rgb_fc(torch::relu(fc_4(c.mean(1))));
}

torch::Tensor HeadsImpl::color_plain(const torch::Tensor& e, const torch::Tensor&,
                                     const torch::Tensor& dir_code, const Products& P) {
  const auto c = Products::fp32(P.linear(e, feature_fc->weight, feature_fc->bias));
  const auto d = dir_code.unsqueeze(1).expand({e.size(0), e.size(1), dir_code.size(1)});
  return rgb_fc(torch::relu(fc_4(torch::relu(view_fc(torch::cat({c, d}, 2))).mean(1))));
}

// ---- folded
// ----------------------------------------------------------------------------------------
// view_fc(cat(c, gamma)) = (view_fc_c . feature_fc) e + view_fc_c rgb_res_0(p) + view_fc_d gamma +
// b

torch::Tensor HeadsImpl::direction_part(const torch::Tensor& dir_code, const Products& P) const {
  return P.linear_fp32(dir_code, view_fc->weight.narrow(1, 256, kDirectionEncodingDim))
      .unsqueeze(1);
}

torch::Tensor HeadsImpl::tail(const torch::Tensor& c, const Products& P) const {
  return P.linear_fp32(P.linear_fp32(c.mean(1), fc_4->weight, fc_4->bias).relu_(), rgb_fc->weight,
                       rgb_fc->bias);
}

torch::Tensor HeadsImpl::color_folded_pixels(const HeadsFolded& f, const torch::Tensor& e,
                                             const torch::Tensor& readout,
                                             const torch::Tensor& dir_code, const Products& P) {
  auto c = Products::fp32(P.linear(e, f.e_weight, f.e_bias)).add_(direction_part(dir_code, P));
  return tail(c.add_(readout.narrow(2, 0, 128)).relu_() + readout.narrow(2, 128, 128), P);
}

torch::Tensor HeadsImpl::color_folded_plain(const HeadsFolded& f, const torch::Tensor& e,
                                            const torch::Tensor&, const torch::Tensor& dir_code,
                                            const Products& P) {
  auto c = Products::fp32(P.linear(e, f.e_weight, f.e_bias)).add_(direction_part(dir_code, P));
  return tail(c.relu_(), P);
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
