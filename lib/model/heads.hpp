#pragma once
// METHOD 3.4, second half: the density head (mean over views, fc_3, alpha_fc) and the colour head
// (feature_fc + rgb_res_0, view directions, view_fc, rgb_res_1, mean, fc_4, rgb_fc).
// All layers are per-point Linear layers on rows (the reference's Conv1d k=1).

#include <torch/torch.h>

#include "model/precision.hpp"

namespace th::model {

// Folded colour weights (exact identities): view_fc's feature part is composed with
// feature_fc and with rgb_res_0, so that the pixel-side layers become one 256-channel readout
// [view_fc_c . rgb_res_0 ; rgb_res_1] of p_v.
struct HeadsFolded {
  torch::Tensor e_weight, e_bias;              // (128, 256), (128): view_fc_c . feature_fc
  torch::Tensor readout_weight, readout_bias;  // (256, Cpix), (256); undefined w/o appearance
};

class HeadsImpl : public torch::nn::Module {
 public:
  // appearance: the rgb_res_* residuals from p_v exist (false for the "w/o a" ablation).
  HeadsImpl(bool appearance, int64_t pixel_channels);

  // e: (N, V, 256) fp32 or bf16 -> raw density (N) fp32. fc_3 in the products' compute type,
  // alpha_fc in fp32 (model/precision.hpp).
  torch::Tensor density(const torch::Tensor& e, const Products& products = {});

  // The reference colour head. e: (N, V, 256); p: (N, V, Cpix) (undefined w/o appearance);
  // dir_code: (N, 27) gamma(d) -> raw rgb (N, 3) fp32. The products on e in the compute type.
  torch::Tensor color(const torch::Tensor& e, const torch::Tensor& p, const torch::Tensor& dir_code,
                      const Products& products = {}) {
    return rgb_res_0 ? color_pixels(e, p, dir_code, products)  // w/o a: no residuals from p_v
                     : color_plain(e, p, dir_code, products);
  }

  // The same from folded weights (fold() below). readout: (N, V, 256) = the folded readout of
  // p_v (undefined w/o appearance).
  torch::Tensor color_folded(const HeadsFolded& folded, const torch::Tensor& e,
                             const torch::Tensor& readout, const torch::Tensor& dir_code,
                             const Products& products = {}) {
    return rgb_res_0 ? color_folded_pixels(folded, e, readout, dir_code, products)
                     : color_folded_plain(folded, e, readout, dir_code, products);
  }

  // METHOD 9: view_fc's feature part composed with feature_fc, and with rgb_res_0 into one
  // 256-channel readout [view_fc_c . rgb_res_0 ; rgb_res_1] of p_v.
  HeadsFolded fold() const { return rgb_res_0 ? fold_pixels() : fold_plain(); }

  torch::nn::Linear fc_3{nullptr}, alpha_fc{nullptr};
  torch::nn::Linear feature_fc{nullptr}, view_fc{nullptr}, fc_4{nullptr}, rgb_fc{nullptr};
  torch::nn::Linear rgb_res_0{nullptr}, rgb_res_1{nullptr};  // null w/o appearance

 private:
  // The colour head with the residuals from p_v, or without them ("w/o a").
  torch::Tensor color_pixels(const torch::Tensor& e, const torch::Tensor& p,
                             const torch::Tensor& dir_code, const Products& products);
  torch::Tensor color_plain(const torch::Tensor& e, const torch::Tensor& p,
                            const torch::Tensor& dir_code, const Products& products);
  torch::Tensor color_folded_pixels(const HeadsFolded& f, const torch::Tensor& e,
                                    const torch::Tensor& readout, const torch::Tensor& dir_code,
                                    const Products& products);
  torch::Tensor color_folded_plain(const HeadsFolded& f, const torch::Tensor& e,
                                   const torch::Tensor& readout, const torch::Tensor& dir_code,
                                   const Products& products);
  HeadsFolded fold_pixels() const;
  HeadsFolded fold_plain() const;
  // Both colour forms: view_fc's direction part, and the tail fc_4, rgb_fc on the view mean.
  torch::Tensor direction_part(const torch::Tensor& dir_code, const Products& products) const;
  torch::Tensor tail(const torch::Tensor& c, const Products& products) const;
};
TORCH_MODULE(Heads);

}  // namespace th::model
