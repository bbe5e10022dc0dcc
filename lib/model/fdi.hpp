#pragma once
// METHOD 3.4, first half: FDI fuses the human representation s_v with the appearance features
// a_v of the reference views by a single-head cross-attention over views (query from s, keys
// and values from a), then the shared trunk e_v = relu(fc_2(relu(fc_1(o_v)))).
// Ablations: "w/o a" (fdi.appearance false): o_v = value1(s_v); "w/o h" (fdi.human false):
// queries are the appearance keys themselves, o_v = u_v + sum_j softmax_j(k_v . k_j) u_j.
// The layers run folded (METHOD 9): fc_1 is linear, so it is folded into both value
// projections, and each key projection shares one product with its value projection.

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

  // The folded weights of this fusion, made once per frame.
  FDIFolded fold() const;
  // e_v from s_v and a_v (N, V, 256) each, undefined where the ablation has no such branch, with
  // the frame's folded weights; the products in `products`' precision. -> (N, V, 256).
  torch::Tensor forward(const FDIFolded& folded, const torch::Tensor& s, const torch::Tensor& a,
                        const Products& products) const;

  torch::nn::Linear alpha_res_0{nullptr};            // appearance: p_v -> a_v (384 -> 256)
  torch::nn::Linear key0{nullptr}, value0{nullptr};  // appearance side (spatial_key_value_0)
  torch::nn::Linear key1{nullptr}, value1{nullptr};  // query side (spatial_key_value_1)
  torch::nn::Linear fc_1{nullptr}, fc_2{nullptr};
};
TORCH_MODULE(FDI);

}  // namespace th::model
