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

namespace {

// The window table of a readout, read from its level table, which is then dropped.
void to_window(const PixelWindows& windows, const torch::Tensor& uv, const torch::Tensor& view,
               const PixelGeometry& g, PixelReadout& r) {
  constexpr int64_t kChunk = 65536;  // window pixels per step: bounds the taps' memory
  r.window_table = torch::empty({windows.rows(), r.table.size(1)}, r.table.options());
  for (int64_t b = 0; b < windows.rows(); b += kChunk) {
    const int64_t e = std::min(windows.rows(), b + kChunk);
    const auto u = uv.slice(0, b, e), v = view.slice(0, b, e);
    r.window_table.slice(0, b, e).copy_(r.sample(g.stacked_level_taps(u, v), g.image_taps(u, v)));
  }
  r.table = torch::Tensor();
}

}  // namespace

void make_pixel_readouts(const EncoderImpl& encoder, const EncodedViews& enc, const FDIImpl& fdi,
                         const HeadsFolded& heads, PixelStage& pixels, const PixelWindows* windows) {
  torch::Tensor uv, view;
  if (windows) std::tie(uv, view) = windows->pixels(enc.images.options());
  // One readout at a time, so that with windows a single level table exists at any moment.
  pixels.alpha = encoder.make_readout(enc, fdi.alpha_res_0->weight, fdi.alpha_res_0->bias);
  if (windows) to_window(*windows, uv, view, pixels.geometry, pixels.alpha);
  pixels.color = encoder.make_readout(enc, heads.readout_weight, heads.readout_bias);
  if (windows) to_window(*windows, uv, view, pixels.geometry, pixels.color);
  pixels.color.image_table = pixels.alpha.image_table;  // one copy of the raw images
  if (windows) {
    pixels.windows = *windows;
    pixels.levels = enc.levels;  // for points outside the windows
    pixels.images = enc.images;
  }
}

PixelWindows body_windows(const FrameGeometry& geo, const torch::Tensor& vertices, double distance,
                          const PixelGeometry& g) {
  TORCH_CHECK(vertices.dim() == 2 && vertices.size(1) == 3, "body_windows: vertices must be (Nv, 3), got ",
              vertices.sizes());
  const auto opts = geo.K.options();
  auto signs = torch::tensor({-1.0, 1.0}, opts);
  const auto grid = torch::meshgrid({signs, signs, signs}, "ij");
  signs = torch::stack({grid[0].flatten(), grid[1].flatten(), grid[2].flatten()}, 1);  // (8, 3)
  const auto corners = (vertices.to(opts).unsqueeze(1) + distance * signs).reshape({-1, 3});
  const auto depth = (torch::matmul(corners.unsqueeze(0), geo.R.transpose(1, 2)) + geo.T.reshape({-1, 1, 3})).select(2, 2);
  const auto uv = project_points(corners, geo.K, geo.R, geo.T);  // (V, 8 Nv, 2)
  PixelWindows w;
  int64_t offset = 0;
  for (int64_t v = 0; v < g.views; ++v) {
    int64_t x0 = 0, y0 = 0, x1 = g.width, y1 = g.height;
    const bool in_front = depth[v].min().item<double>() > 0 && uv[v].isfinite().all().item<bool>();
    if (in_front && corners.size(0) > 0) {
      const auto lo = std::get<0>(uv[v].min(0)), hi = std::get<0>(uv[v].max(0));
      auto clampi = [](double x, int64_t n) { return std::min<int64_t>(std::max<double>(x, 0), n); };
      x0 = clampi(std::floor(lo[0].item<double>()) - 1, g.width);
      y0 = clampi(std::floor(lo[1].item<double>()) - 1, g.height);
      x1 = std::max(x0, clampi(std::ceil(hi[0].item<double>()) + 2, g.width));
      y1 = std::max(y0, clampi(std::ceil(hi[1].item<double>()) + 2, g.height));
    }
    w.x0.push_back(x0);
    w.y0.push_back(y0);
    w.w.push_back(x1 - x0);
    w.h.push_back(y1 - y0);
    w.offset.push_back(offset);
    offset += (x1 - x0) * (y1 - y0);
  }
  return w;
}

}  // namespace th::model
