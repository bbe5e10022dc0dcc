#pragma once
// METHOD 3.4, second half: the density head (mean over views, fc_3, alpha_fc) and the colour head
// (feature_fc + rgb_res_0, view directions, view_fc, rgb_res_1, mean, fc_4, rgb_fc).
// All layers are per-point Linear layers on rows (the reference's Conv1d k=1), run folded
// (METHOD 9).

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

  // METHOD 9: view_fc's feature part composed with feature_fc, and with rgb_res_0 into one
  // 256-channel readout [view_fc_c . rgb_res_0 ; rgb_res_1] of p_v.
  HeadsFolded fold() const;

  // The density head: e_v (N, V, 256) -> sigma_raw (N) fp32.
  torch::Tensor density(const torch::Tensor& e, const Products& products) const;
  // The colour head: e_v, the folded readout of p_v at the points (N, V, 256; undefined w/o
  // appearance) and gamma(d) (N, 27) -> rgb logits (N, 3) fp32; gamma(d) (K, N, 27) of K
  // directions per point -> (K, N, 3), the part before the direction made once.
  torch::Tensor colour(const HeadsFolded& folded, const torch::Tensor& e,
                       const torch::Tensor& readout, const torch::Tensor& dir_code,
                       const Products& products) const;

  torch::nn::Linear fc_3{nullptr}, alpha_fc{nullptr};
  torch::nn::Linear feature_fc{nullptr}, view_fc{nullptr}, fc_4{nullptr}, rgb_fc{nullptr};
  torch::nn::Linear rgb_res_0{nullptr}, rgb_res_1{nullptr};  // null w/o appearance
};
TORCH_MODULE(Heads);

}  // namespace th::model
