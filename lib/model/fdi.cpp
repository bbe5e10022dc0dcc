#include "model/fdi.hpp"

#include <cmath>

namespace th::model {

namespace F = torch::nn::functional;

FDIImpl::FDIImpl(const FDIConfig& config_, int64_t pixel_channels) : config(config_) {
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

torch::Tensor FDIImpl::attention(const torch::Tensor& q, const torch::Tensor& k) {
  const double scale = 1.0 / std::sqrt(static_cast<double>(q.size(2)));
  return torch::softmax(torch::bmm(q, k.transpose(1, 2)) * scale, 2);
}

torch::Tensor FDIImpl::forward(const torch::Tensor& s, const torch::Tensor& a) {
  torch::Tensor o;
  if (config.appearance && config.human) {
    const auto att = attention(key1(s), key0(a));
    o = value1(s) + torch::bmm(att, value0(a));
  } else if (config.appearance) {
    const auto k = key0(a);
    o = value0(a);
    o = o + torch::bmm(attention(k, k), o);
  } else {
    o = value1(s);
  }
  return torch::relu(fc_2(torch::relu(fc_1(o))));
}

FDIFolded FDIImpl::fold() const {
  FDIFolded f;
  const auto& W1 = fc_1->weight;
  if (config.appearance) {
    f.w0 = torch::cat({key0->weight, torch::mm(W1, value0->weight)}, 0);
    f.b0 = torch::cat({key0->bias, torch::mv(W1, value0->bias)}, 0);
  }
  if (config.human) {
    // fc_1's bias joins the query side (the attention weights multiply the value side).
    const auto wv = torch::mm(W1, value1->weight);
    const auto bv = torch::mv(W1, value1->bias) + fc_1->bias;
    f.w1 = config.appearance ? torch::cat({key1->weight, wv}, 0) : wv;
    f.b1 = config.appearance ? torch::cat({key1->bias, bv}, 0) : bv;
  }
  return f;
}

torch::Tensor FDIImpl::forward_folded(const FDIFolded& f, const torch::Tensor& s, const torch::Tensor& a) {
  torch::Tensor pre;
  if (config.appearance && config.human) {
    const auto kv = F::linear(a, f.w0, f.b0);  // (N, V, 128 + 256)
    const auto qr = F::linear(s, f.w1, f.b1);
    const auto att = attention(qr.narrow(2, 0, 128), kv.narrow(2, 0, 128));
    pre = torch::baddbmm(qr.narrow(2, 128, 256), att, kv.narrow(2, 128, 256));
  } else if (config.appearance) {
    const auto kv = F::linear(a, f.w0, f.b0);
    const auto k = kv.narrow(2, 0, 128), u = kv.narrow(2, 128, 256);
    pre = torch::baddbmm(u + fc_1->bias, attention(k, k), u);
  } else {
    pre = F::linear(s, f.w1, f.b1);
  }
  return fc_2(pre.relu_()).relu_();
}

}  // namespace th::model
