#include "model/fdi.hpp"

#include "model/kernels/view_attention.hpp"
#include "model/kernels/work.hpp"

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
// weights multiply the value side), the appearance side otherwise ("w/o h" adds it in forward).
FDIFolded FDIImpl::fold() const {
  const auto& W1 = fc_1->weight;
  FDIFolded f;
  if (key0) {
    f.w0 = torch::cat({key0->weight, torch::mm(W1, value0->weight)}, 0);
    f.b0 = torch::cat({key0->bias, torch::mv(W1, value0->bias)}, 0);
  }
  if (value1) {
    const auto w = torch::mm(W1, value1->weight), b = torch::mv(W1, value1->bias) + fc_1->bias;
    f.w1 = key0 ? torch::cat({key1->weight, w}, 0) : w;  // w/o a: no attention, no key
    f.b1 = key0 ? torch::cat({key1->bias, b}, 0) : b;
  }
  return f;
}

// o_v = r_v + sum_j softmax_j(q_v . k_j / sqrt(d)) u_j with q, r from s_v and k, u from a_v;
// fc_1 is already in r and u (and its bias in r), so `pre` is fc_1(o_v) before its ReLU.
torch::Tensor FDIImpl::forward(const FDIFolded& f, const torch::Tensor& s, const torch::Tensor& a,
                               const Products& P) const {
  const int64_t d = key0 ? key0->weight.size(0) : 0;  // the attention's key width
  torch::Tensor pre;                                  // relu(fc_1(o_v))
  if (key0 && key1) {  // the kernel reads the products' type and writes it, clamped
    pre = kernels::view_attention(P.linear(s, f.w1, f.b1), P.linear(a, f.w0, f.b0), d, true);
  } else if (key0) {  // w/o h: the appearance keys attend to each other
    const auto kv = Products::fp32(P.linear(a, f.w0, f.b0));
    const auto k = kv.narrow(2, 0, d), u = kv.narrow(2, d, kv.size(2) - d);
    pre = torch::baddbmm(u + fc_1->bias, kernels::view_attention_weights(k, k), u).relu_();
  } else {  // w/o a: fc_1(value1(s_v))
    pre = P.linear(s, f.w1, f.b1).relu_();
  }
  auto e = P.linear(pre, fc_2->weight, fc_2->bias).relu_();  // e_v
  kernels::count_elementwise(e, 1);
  return e;
}

}  // namespace th::model
