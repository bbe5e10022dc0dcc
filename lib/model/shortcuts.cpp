#include "model/shortcuts.hpp"

#include "model/encoder.hpp"
#include "model/fdi.hpp"
#include "model/heads.hpp"

namespace th::model {

torch::Tensor token_table(const torch::Tensor& tokens, const torch::nn::Linear& fc_0) {
  const auto C = tokens.size(2);
  const auto w_tok = fc_0->weight.narrow(1, 0, C);
  const auto table = torch::matmul(tokens, w_tok.t()) + fc_0->bias;  // (V, Nt, 256)
  return table.permute({1, 0, 2}).reshape({table.size(1), -1});
}

FDIFolded fold_fdi(const FDIImpl& fdi) {
  FDIFolded f;
  const auto& W1 = fdi.fc_1->weight;
  if (fdi.config.appearance) {
    f.w0 = torch::cat({fdi.key0->weight, torch::mm(W1, fdi.value0->weight)}, 0);
    f.b0 = torch::cat({fdi.key0->bias, torch::mv(W1, fdi.value0->bias)}, 0);
  }
  if (fdi.config.human) {
    // fc_1's bias joins the query side (the attention weights multiply the value side).
    const auto wv = torch::mm(W1, fdi.value1->weight);
    const auto bv = torch::mv(W1, fdi.value1->bias) + fdi.fc_1->bias;
    f.w1 = fdi.config.appearance ? torch::cat({fdi.key1->weight, wv}, 0) : wv;
    f.b1 = fdi.config.appearance ? torch::cat({fdi.key1->bias, bv}, 0) : bv;
  }
  return f;
}

HeadsFolded fold_heads(const HeadsImpl& heads) {
  HeadsFolded f;
  const auto wc = heads.view_fc->weight.narrow(1, 0, 256);
  f.e_weight = torch::mm(wc, heads.feature_fc->weight);
  f.e_bias = torch::mv(wc, heads.feature_fc->bias) + heads.view_fc->bias;
  if (heads.appearance()) {
    f.readout_weight = torch::cat({torch::mm(wc, heads.rgb_res_0->weight), heads.rgb_res_1->weight}, 0);
    f.readout_bias = torch::cat({torch::mv(wc, heads.rgb_res_0->bias), heads.rgb_res_1->bias}, 0);
  }
  return f;
}

FoldedWeights fold_weights(const FDIImpl& fdi, const HeadsImpl& heads) { return {fold_fdi(fdi), fold_heads(heads)}; }

void make_pixel_readouts(const EncoderImpl& encoder, const EncodedViews& enc, const FDIImpl& fdi,
                         const HeadsFolded& heads, PixelStage& pixels) {
  pixels.alpha = encoder.make_readout(enc, fdi.alpha_res_0->weight, fdi.alpha_res_0->bias);
  pixels.color = encoder.make_readout(enc, heads.readout_weight, heads.readout_bias);
  pixels.color.image_table = pixels.alpha.image_table;  // one copy of the raw images
}

}  // namespace th::model
