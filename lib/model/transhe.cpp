#include "model/transhe.hpp"

#include <cmath>

#include "model/kernels/encoding.hpp"

namespace th::model {
namespace {

namespace F = torch::nn::functional;

void init_linear(torch::nn::Linear& l) {
  torch::NoGradGuard no_grad;
  trunc_normal_(l->weight, 0.02);
  if (l->bias.defined()) l->bias.zero_();
}

torch::nn::LayerNorm layer_norm(int64_t dim) {
  return torch::nn::LayerNorm(torch::nn::LayerNormOptions({dim}).eps(1e-6));
}

}  // namespace

void trunc_normal_(torch::Tensor& t, double std, double a, double b) {
  torch::NoGradGuard no_grad;
  auto cdf = [](double x) { return (1.0 + std::erf(x / std::sqrt(2.0))) / 2.0; };
  const double l = cdf(a / std), u = cdf(b / std);
  t.uniform_(2 * l - 1, 2 * u - 1).erfinv_().mul_(std * std::sqrt(2.0)).clamp_(a, b);
}

torch::Tensor cluster_counts(const torch::Tensor& labels, int64_t num_tokens) {
  return torch::bincount(labels, {}, num_tokens).narrow(0, 0, num_tokens);
}

torch::Tensor cluster_mean(const torch::Tensor& values, const torch::Tensor& labels,
                           int64_t num_tokens, const torch::Tensor& weights) {
  const auto nv = labels.size(0);
  TORCH_CHECK(values.dim() >= 2 && values.size(-2) == nv, "cluster_mean values must be (..., ", nv,
              ", C), got ", values.sizes());
  const auto lead = values.sizes().slice(0, values.dim() - 2).vec();
  const auto flat = values.reshape({-1, nv, values.size(-1)});  // (B, Nv, C)
  const auto B = flat.size(0);
  auto shape = lead;
  shape.push_back(num_tokens);
  shape.push_back(values.size(-1));
  torch::Tensor sums, counts;
  if (weights.defined()) {
    const auto w = weights.reshape({B, nv}).to(values.dtype());
    sums = torch::zeros({B, num_tokens, flat.size(2)}, values.options())
               .index_add(1, labels, flat * w.unsqueeze(-1));
    counts = torch::zeros({B, num_tokens}, values.options()).index_add(1, labels, w);
  } else {
    sums = torch::zeros({B, num_tokens, flat.size(2)}, values.options()).index_add(1, labels, flat);
    counts =
        cluster_counts(labels, num_tokens).to(values.dtype()).unsqueeze(0).expand({B, num_tokens});
  }
  return (sums / counts.clamp_min(1).unsqueeze(-1)).view(shape);
}

torch::Tensor normalize_token_positions(const torch::Tensor& p, double scale,
                                        const torch::Tensor& like) {
  const auto d = p.to(torch::kDouble);
  return ((((d + scale) / (2 * scale)) - 0.5) * 2).to(like.scalar_type());
}

AttentionImpl::AttentionImpl(int64_t dim, int64_t heads_) : heads(heads_) {
  qkv =
      register_module("qkv", torch::nn::Linear(torch::nn::LinearOptions(dim, 3 * dim).bias(true)));
  proj = register_module("proj", torch::nn::Linear(dim, dim));
  init_linear(qkv);
  init_linear(proj);
}

torch::Tensor AttentionImpl::forward(const torch::Tensor& x) {
  const auto B = x.size(0), N = x.size(1), C = x.size(2);
  const auto qkv_ = qkv(x).reshape({B, N, 3, heads, C / heads}).permute({2, 0, 3, 1, 4});
  const auto q = qkv_[0], k = qkv_[1], v = qkv_[2];
  const double scale = 1.0 / std::sqrt(static_cast<double>(C / heads));
  const auto attn = torch::softmax(torch::matmul(q, k.transpose(-2, -1)) * scale, -1);
  return proj(torch::matmul(attn, v).transpose(1, 2).reshape({B, N, C}));
}

MlpImpl::MlpImpl(int64_t dim, int64_t hidden) {
  fc1 = register_module("fc1", torch::nn::Linear(dim, hidden));
  fc2 = register_module("fc2", torch::nn::Linear(hidden, dim));
  init_linear(fc1);
  init_linear(fc2);
}

torch::Tensor MlpImpl::forward(const torch::Tensor& x) { return fc2(torch::gelu(fc1(x))); }

BlockImpl::BlockImpl(int64_t dim, int64_t heads, int64_t mlp_dim) {
  norm1 = register_module("norm1", layer_norm(dim));
  attn = register_module("attn", Attention(dim, heads));
  norm2 = register_module("norm2", layer_norm(dim));
  mlp = register_module("mlp", Mlp(dim, mlp_dim));
}

torch::Tensor BlockImpl::forward(const torch::Tensor& x) {
  auto y = x + attn(norm1(x));
  return y + mlp(norm2(y));
}

TransHEImpl::TransHEImpl(const TransHEConfig& config_) : config(config_) {
  blocks = register_module("blocks", torch::nn::ModuleList());
  for (int i = 0; i < config.depth; ++i)
    blocks->push_back(Block(config.dim, config.heads, config.mlp_dim));
  norm = register_module("norm", layer_norm(config.dim));
}

torch::Tensor TransHEImpl::encode_positions(const torch::Tensor& positions) const {
  return kernels::sincos_encoding(positions, config.pe_freqs, false,
                                  config.pe_rounding == PeRounding::fused);
}

torch::Tensor TransHEImpl::forward(const torch::Tensor& tokens, const torch::Tensor& positions) {
  TORCH_CHECK(tokens.dim() == 3 && tokens.size(2) == config.dim, "TransHE tokens must be (V, Nt, ",
              config.dim, "), got ", tokens.sizes());
  TORCH_CHECK(positions.dim() == 2 && positions.size(0) == tokens.size(1),
              "TransHE positions must be (", tokens.size(1), ", 3), got ", positions.sizes());
  auto x = tokens + encode_positions(positions).unsqueeze(0);
  for (const auto& block : *blocks) x = block->as<Block>()->forward(x);
  return norm(x);
}

}  // namespace th::model
