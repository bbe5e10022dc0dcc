#pragma once
// METHOD 3.2: TransHE. Painted vertex features are averaged per token (cluster), the canonical
// token positions are sine-cosine encoded, and a ViT-Tiny (timm layout and names) processes
// each view's token sequence independently.

#include <torch/torch.h>

#include "core/config.hpp"

namespace th::model {

// Per-cluster means. values: (..., Nv, C), labels: (Nv) int64 in [0, num_tokens) ->
// (..., num_tokens, C). Empty clusters give 0. With `weights` (..., Nv) (e.g. visibility) the
// mean is weighted (option mean_over: visible); otherwise every vertex counts [parity].
torch::Tensor cluster_mean(const torch::Tensor& values, const torch::Tensor& labels,
                           int64_t num_tokens, const torch::Tensor& weights = {});

// Vertices per cluster: (num_tokens) int64.
torch::Tensor cluster_counts(const torch::Tensor& labels, int64_t num_tokens);

// Token position normalisation of the reference: ((p + 1.5) / 3 - 0.5) * 2, evaluated in
// float64 and rounded to float32 once [parity: the high PE frequencies see every ulp].
// p: (Nt, 3) float64 cluster means -> (Nt, 3) in the dtype of `like`.
torch::Tensor normalize_token_positions(const torch::Tensor& p, double scale,
                                        const torch::Tensor& like);

class AttentionImpl : public torch::nn::Module {
 public:
  AttentionImpl(int64_t dim, int64_t heads);
  torch::Tensor forward(const torch::Tensor& x);  // (B, N, dim) -> (B, N, dim)
  torch::nn::Linear qkv{nullptr}, proj{nullptr};
  int64_t heads;
};
TORCH_MODULE(Attention);

class MlpImpl : public torch::nn::Module {
 public:
  MlpImpl(int64_t dim, int64_t hidden);
  torch::Tensor forward(const torch::Tensor& x);
  torch::nn::Linear fc1{nullptr}, fc2{nullptr};
};
TORCH_MODULE(Mlp);

// Pre-norm block: x + attn(norm1(x)), then x + mlp(norm2(x)); LayerNorm eps 1e-6, exact GELU.
class BlockImpl : public torch::nn::Module {
 public:
  BlockImpl(int64_t dim, int64_t heads, int64_t mlp_dim);
  torch::Tensor forward(const torch::Tensor& x);
  torch::nn::LayerNorm norm1{nullptr}, norm2{nullptr};
  Attention attn{nullptr};
  Mlp mlp{nullptr};
};
TORCH_MODULE(Block);

// ViT-Tiny without CLS token; the positional encoding of the token positions is added to the
// tokens. Parameters named as the reference's `ViT.*` (blocks.{i}..., norm).
class TransHEImpl : public torch::nn::Module {
 public:
  explicit TransHEImpl(const TransHEConfig& config);

  // tokens: (V, Nt, dim), positions: (Nt, 3) normalised -> (V, Nt, dim).
  torch::Tensor forward(const torch::Tensor& tokens, const torch::Tensor& positions);
  // The positional encoding added to the tokens: (Nt, 3) -> (Nt, dim).
  torch::Tensor encode_positions(const torch::Tensor& positions) const;

  torch::nn::ModuleList blocks{nullptr};
  torch::nn::LayerNorm norm{nullptr};
  TransHEConfig config;
};
TORCH_MODULE(TransHE);

// timm's trunc_normal_(std, a=-2, b=2) by the inverse-CDF method.
void trunc_normal_(torch::Tensor& t, double std, double a = -2.0, double b = 2.0);

}  // namespace th::model
