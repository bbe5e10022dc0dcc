#include "model/heads.hpp"

#include "model/kernels/encoding.hpp"
#include "model/kernels/view_mean.hpp"
#include "model/kernels/work.hpp"

namespace th::model {

HeadsImpl::HeadsImpl(bool appearance, int64_t pixel_channels) {
  fc_3 = register_module("fc_3", torch::nn::Linear(256, 256));
  alpha_fc = register_module("alpha_fc", torch::nn::Linear(256, 1));
  feature_fc = register_module("feature_fc", torch::nn::Linear(256, 256));
  view_fc =
      register_module("view_fc", torch::nn::Linear(256 + kernels::kDirectionEncodingDim, 128));
  fc_4 = register_module("fc_4", torch::nn::Linear(128, 128));
  rgb_fc = register_module("rgb_fc", torch::nn::Linear(128, 3));
  if (appearance) {
    rgb_res_0 = register_module("rgb_res_0", torch::nn::Linear(pixel_channels, 256));
    rgb_res_1 = register_module("rgb_res_1", torch::nn::Linear(pixel_channels, 128));
  }
}

HeadsFolded HeadsImpl::fold() const {
  HeadsFolded f;
  const auto wc = view_fc->weight.narrow(1, 0, 256);
  f.e_weight = torch::mm(wc, feature_fc->weight);
  f.e_bias = torch::mv(wc, feature_fc->bias) + view_fc->bias;
  if (rgb_res_0) {  // w/o a: no readout of p_v
    // A view of its own: view_fc's gradient then sums the two folds' parts in a fixed order.
    const auto wr = view_fc->weight.narrow(1, 0, 256);
    f.readout_weight = torch::cat({torch::mm(wr, rgb_res_0->weight), rgb_res_1->weight}, 0);
    f.readout_bias = torch::cat({torch::mv(wr, rgb_res_0->bias), rgb_res_1->bias}, 0);
  }
  return f;
}

torch::Tensor HeadsImpl::density(const torch::Tensor& e, const Products& P) const {
  const auto h = P.linear(kernels::view_mean(e), fc_3->weight, fc_3->bias).relu_();
  kernels::count_elementwise(h, 1);
  return P.linear_fp32(h, alpha_fc->weight, alpha_fc->bias).squeeze(1);
}

// view_fc(cat(c, gamma)) = (view_fc_c . feature_fc) e + view_fc_c rgb_res_0(p) + view_fc_d gamma
// + b, with the pixel side read as one readout [view_fc_c . rgb_res_0 ; rgb_res_1] of p_v. The
// product with e does not depend on the direction: it is made once for all the directions.
torch::Tensor HeadsImpl::colour(const HeadsFolded& f, const torch::Tensor& e,
                                const torch::Tensor& readout, const torch::Tensor& dir_code,
                                const Products& P) const {
  const bool many = dir_code.dim() == 3;
  const auto codes = many ? dir_code : dir_code.unsqueeze(0);
  const auto base = P.linear(e, f.e_weight, f.e_bias);  // the kernel reads bf16 or fp32
  std::vector<torch::Tensor> rgb;
  for (int64_t k = 0; k < codes.size(0); ++k) {
    const auto direction =
        P.linear_fp32(codes[k], view_fc->weight.narrow(1, 256, kernels::kDirectionEncodingDim));
    // mean over v of relu(c_v) + rgb_res_1(p_v), or of relu(c_v) w/o a (no readout of p_v)
    const auto c = kernels::colour_mean(base, direction, rgb_res_0 ? readout : torch::Tensor());
    const auto h = P.linear_fp32(c, fc_4->weight, fc_4->bias).relu_();
    kernels::count_elementwise(h, 1);
    rgb.push_back(P.linear_fp32(h, rgb_fc->weight, rgb_fc->bias));
  }
  return many ? torch::stack(rgb) : rgb[0];
}

}  // namespace th::model
