#pragma once
// METHOD 3.4, first half: FDI fuses the human representation s_v with the appearance features
// a_v of the reference views by a single-head cross-attention over views (query from s, keys
// and values from a), then the shared trunk e_v = relu(fc_2(relu(fc_1(o_v)))).
// Ablations: "w/o a" (fdi.appearance false): o_v = value1(s_v); "w/o h" (fdi.human false):
// queries are the appearance keys themselves, o_v = u_v + sum_j softmax_j(k_v . k_j) u_j.

#include <torch/torch.h>

#include "core/config.hpp"
#include "model/precision.hpp"

namespace th::model {

// Per-frame products of layer weights (exact identities: fc_1 is linear, so it is folded into
// the value projections; key and value projections share one matrix product).
struct FDIFolded {
  torch::Tensor w0, b0;  // appearance side: [key0; fc_1 value0]   (384, 256), (384)
  torch::Tensor w1, b1;  // query side:      [key1; fc_1 value1]   (384, 256) / (256, 256)
};

class FDIImpl : public torch::nn::Module {
 public:
  FDIImpl(const FDIConfig& config, int64_t pixel_channels);

  // The reference computation. s, a: (N, V, 256) (undefined when the branch is off)
  // -> e: (N, V, 256), in the products' compute type (model/precision.hpp).
  torch::Tensor forward(const torch::Tensor& s, const torch::Tensor& a,
                        const Products& products = {});

  // The same from folded weights (fewer matrix products; model/shortcuts.hpp folds them).
  torch::Tensor forward_folded(const FDIFolded& folded, const torch::Tensor& s,
                               const torch::Tensor& a, const Products& products = {});

  // softmax over the key views j of q_v . k_j / sqrt(d): q (N, V, d), k (N, V, d) -> (N, V, V)
  // indexed [n, v (query), j (key)].
  static torch::Tensor attention(const torch::Tensor& q, const torch::Tensor& k);
  // r_v + sum_j attention(q, k)[v, j] u_j with qr = [q | r], kv = [k | u] packed along the
  // channels: (N, V, d + C) each -> (N, V, C). On CPU a fused per-point kernel with its own
  // backward (batched products of the tiny per-point matrices are slow); elsewhere bmm.
  static torch::Tensor attend(const torch::Tensor& qr, const torch::Tensor& kv, int64_t d);

  // The folded weights of this fusion (model/shortcuts.hpp folds them once per frame).
  FDIFolded fold() const;

  torch::nn::Linear alpha_res_0{nullptr};            // appearance: p_v -> a_v (384 -> 256)
  torch::nn::Linear key0{nullptr}, value0{nullptr};  // appearance side (spatial_key_value_0)
  torch::nn::Linear key1{nullptr}, value1{nullptr};  // query side (spatial_key_value_1)
  torch::nn::Linear fc_1{nullptr}, fc_2{nullptr};

 private:
  // One fusion of s and a (the paper's, and each ablation's), in its three forms: o_v from the
  // layers, fc_1's input pre-activation from folded weights, and the folding itself. Which one
  // runs follows from the branches the module has (FDIConfig): forward, forward_folded, fold.
  // Cross-attention over the views: queries from s, keys and values from a (the paper's).
  torch::Tensor cross(const torch::Tensor& s, const torch::Tensor& a, const Products& p);
  torch::Tensor cross_folded(const FDIFolded& f, const torch::Tensor& s, const torch::Tensor& a,
                             const Products& p);
  FDIFolded fold_cross() const;
  // "w/o h": self-attention of the appearance features.
  torch::Tensor self(const torch::Tensor& s, const torch::Tensor& a, const Products& p);
  torch::Tensor self_folded(const FDIFolded& f, const torch::Tensor& s, const torch::Tensor& a,
                            const Products& p);
  FDIFolded fold_self() const;
  // "w/o a": o_v = value1(s_v).
  torch::Tensor human_only(const torch::Tensor& s, const torch::Tensor& a, const Products& p);
  torch::Tensor human_only_folded(const FDIFolded& f, const torch::Tensor& s,
                                  const torch::Tensor& a, const Products& p);
  FDIFolded fold_human_only() const;
};
TORCH_MODULE(FDI);

}  // namespace th::model
