#include "model/plan.hpp"

#include "geometry/camera.hpp"
#include "model/kernels/gather.hpp"
#include "model/kernels/view_attention.hpp"
#include "model/positional_encoding.hpp"
#include "model/shortcuts.hpp"
#include "model/transhuman.hpp"
#include "render/volume.hpp"

namespace th::model {
namespace {

namespace F = torch::nn::functional;

torch::Tensor affine(const torch::nn::Linear& l, const torch::Tensor& x) {
  return F::linear(x, l->weight, l->bias);
}

// A readout's values at uv (N, V, 2), read from its level tables.
torch::Tensor read_levels(const PixelReadouts& px, const PixelReadout& readout,
                          const torch::Tensor& uv) {
  const auto [flat, view] = PixelGeometry::point_view_rows(uv);
  return readout
      .sample(px.geometry.stacked_level_taps(flat, view), px.geometry.image_taps(flat, view))
      .view({uv.size(0), uv.size(1), -1});
}

}  // namespace

Plan::Plan(TransHumanImpl& model, const PlanTarget& target) : model_(model), target_(target) {
  const auto& config = model.config();
  folded_ = config.exact_shortcuts;
  fast_painting_ = config.encoder.fast_sampling;
  if (!config.fdi.appearance)
    pixel_form_ = PixelForm::none;
  else if (config.exact_shortcuts)
    pixel_form_ = config.readout_windows && !target.training && target.cpu_kernels
                      ? PixelForm::windows
                      : PixelForm::readouts;
  else
    pixel_form_ = config.encoder.fast_sampling ? PixelForm::levels : PixelForm::map;
}

const char* Plan::pixel_form() const {
  switch (pixel_form_) {
    case PixelForm::none:
      return "no pixels";
    case PixelForm::map:
      return "pixel map";
    case PixelForm::levels:
      return "pixel levels";
    case PixelForm::readouts:
      return "pixel readouts";
    case PixelForm::windows:
      return "readout windows";
  }
  return "";
}

torch::Tensor Plan::layer(const torch::nn::Linear& l, const torch::Tensor& x) const {
  return target_.products.linear(x, l->weight, l->bias);
}

torch::Tensor Plan::layer_fp32(const torch::nn::Linear& l, const torch::Tensor& x) const {
  return Products::fp32(layer(l, x));
}

// ---- per frame ----------------------------------------------------------------------------------

EncodedViews Plan::encode(const torch::Tensor& images) const {
  EncodedViews enc;
  {
    FrameAutocast autocast(target_.products, images.device());
    enc = model_.encoder->forward(images);
  }
  for (auto& level : enc.levels) level = Products::fp32(level);
  return enc;
}

torch::Tensor Plan::paint(const EncodedViews& enc, const torch::Tensor& uv,
                          const torch::Tensor& visibility) const {
  // Sampled from the levels (encoder.fast_sampling), or from the reference's materialised
  // reduction map.
  return fast_painting_ ? model_.encoder->paint(enc, uv, visibility)
                        : model_.encoder->paint_direct(enc, uv, visibility);
}

HumanStage Plan::represent(const FrameInputs& in, const PaintedBody& body) const {
  HumanStage stage;
  {
    FrameAutocast autocast(target_.products, body.features.device());
    stage = model_.human->prepare(in, body);
  }
  std::visit(
      [](auto& s) {
        s.visit([](torch::Tensor& t, torch::Tensor*) {
          if (t.defined()) t = Products::fp32(t);
        });
      },
      stage);
  return stage;
}

NetworkStage Plan::weights() const {
  if (folded_) return fold_weights(*model_.fdi, *model_.heads);
  return LayerWeights{};
}

PixelStage Plan::pixels(const EncodedViews& enc, const FrameGeometry& geometry,
                        const torch::Tensor& vertices, double cull_distance,
                        const NetworkStage& network) const {
  const auto& encoder = *model_.encoder;
  switch (pixel_form_) {
    case PixelForm::none:
      return NoPixels{};
    case PixelForm::map:
      return PixelMap{encoder.pixel_features(enc)};
    case PixelForm::levels:
      return PixelLevels{enc};
    case PixelForm::windows:
      if (cull_distance > 0) {  // points bounded to the body's surroundings
        const auto windows = body_windows(geometry, vertices, cull_distance, enc.geometry);
        return make_window_readouts(encoder, enc, *model_.fdi,
                                    std::get<FoldedWeights>(network).heads, windows);
      }
      [[fallthrough]];
    case PixelForm::readouts:
      return make_pixel_readouts(encoder, enc, *model_.fdi, std::get<FoldedWeights>(network).heads);
  }
  return NoPixels{};
}

// ---- per point: the human representation -------------------------------------------------------

torch::Tensor Plan::human(const FrameCache& frame, const torch::Tensor& xs) const {
  if (const auto* table = std::get_if<TokenTableStage>(&frame.human))
    return token_table_fields(*table, xs);
  return model_.human->forward(frame.human, xs);  // the representation's own layers
}

// METHOD 9's token table: the table's rows of the Nk nearest fields, then fc_0's coordinate part.
torch::Tensor Plan::token_table_fields(const TokenTableStage& stage,
                                       const torch::Tensor& xs) const {
  const auto& fields = dynamic_cast<const TokenFieldsImpl&>(*model_.human);
  const auto q = fields.dparf.query(stage.frames, xs);
  auto s = kernels::weighted_gather(stage.table, {q.index, q.weight}, stage.table_grad_sink)
               .view({xs.size(0), -1, 256});
  if (q.coords.defined()) {
    const auto& w = fields.fc_0->weight;
    const auto G = q.coords.size(1);
    s.add_(target_.products.linear_fp32(q.coords, w.narrow(1, w.size(1) - G, G)).unsqueeze(1));
  }
  return s.relu_();
}

// ---- per point: what sampling reads of the pixels ----------------------------------------------

torch::Tensor Plan::read_windows(const WindowReadouts& px, const WindowReadout& readout,
                                 const torch::Tensor& uv) const {
  const auto [flat, view] = PixelGeometry::point_view_rows(uv);
  const auto& g = px.levels.enc.geometry;
  const auto [taps, inside] = px.windows.taps(flat, view, g.height, g.width);
  auto out = kernels::weighted_gather(readout.table, taps);
  if (!inside.all().item<bool>()) {  // outside the windows: the layer on p_v read from the levels
    const auto idx = (~inside).nonzero().flatten();
    const auto f = flat.index_select(0, idx), v = view.index_select(0, idx);
    const auto p = model_.encoder->sample_pixel_features(px.levels.enc, g.stacked_level_taps(f, v),
                                                         g.image_taps(f, v));
    out.index_copy_(0, idx, F::linear(p, readout.weight, readout.layer_bias));
  }
  return out.view({uv.size(0), uv.size(1), -1});
}

torch::Tensor Plan::colour_pixels(const FrameCache& frame, const torch::Tensor& uv) const {
  const auto& stage = frame.pixels;
  if (const auto* px = std::get_if<PixelMap>(&stage)) return grid_sample_pixels(px->pixel, uv);
  if (const auto* px = std::get_if<PixelLevels>(&stage))
    return model_.encoder->sample_pixel_features(px->enc, uv);
  if (const auto* px = std::get_if<PixelReadouts>(&stage)) return read_levels(*px, px->color, uv);
  if (const auto* px = std::get_if<WindowReadouts>(&stage)) return read_windows(*px, px->color, uv);
  return {};  // NoPixels
}

torch::Tensor Plan::appearance(const FrameCache& frame, const torch::Tensor& uv) const {
  const auto& stage = frame.pixels;
  if (const auto* px = std::get_if<PixelReadouts>(&stage)) return read_levels(*px, px->alpha, uv);
  if (const auto* px = std::get_if<WindowReadouts>(&stage)) return read_windows(*px, px->alpha, uv);
  if (std::holds_alternative<NoPixels>(stage)) return {};
  // p_v itself (map or levels), then alpha_res_0
  return affine(model_.fdi->alpha_res_0, Plan::colour_pixels(frame, uv));
}

// ---- per point: FDI ----------------------------------------------------------------------------

torch::Tensor Plan::fuse(const FrameCache& frame, const torch::Tensor& s,
                         const torch::Tensor& a) const {
  if (const auto* folded = std::get_if<FoldedWeights>(&frame.network))
    return fuse_folded(folded->fdi, s, a);
  return fuse_layers(s, a);
}

// The layers' own weights: products in the compute type, scores and softmax in fp32.
torch::Tensor Plan::fuse_layers(const torch::Tensor& s, const torch::Tensor& a) const {
  const auto& fdi = *model_.fdi;
  torch::Tensor o;
  if (fdi.key0 && fdi.key1) {  // the paper's cross-attention: queries from s, keys/values from a
    const auto att =
        kernels::view_attention_weights(layer_fp32(fdi.key1, s), layer_fp32(fdi.key0, a));
    o = layer_fp32(fdi.value1, s) + torch::bmm(att, layer_fp32(fdi.value0, a));
  } else if (fdi.key0) {  // "w/o h": self-attention of the appearance features
    const auto k = layer_fp32(fdi.key0, a);
    const auto u = layer_fp32(fdi.value0, a);
    o = u + torch::bmm(kernels::view_attention_weights(k, k), u);
  } else {  // "w/o a": o_v = value1(s_v)
    o = affine(fdi.value1, s);
  }
  return torch::relu(layer(fdi.fc_2, torch::relu(layer(fdi.fc_1, o))));
}

// Folded weights (METHOD 9): fc_1 folded into the value projections, each key projection sharing
// one product with its value projection; fc_1's bias joins the query side.
torch::Tensor Plan::fuse_folded(const FDIFolded& f, const torch::Tensor& s,
                                const torch::Tensor& a) const {
  const auto& P = target_.products;
  const auto& fdi = *model_.fdi;
  torch::Tensor pre;  // fc_1's output before its ReLU
  if (fdi.key0 && fdi.key1) {
    // (N, V, 128 + 256) each; the attention kernel takes fp32
    const auto kv = Products::fp32(P.linear(a, f.w0, f.b0));
    const auto qr = Products::fp32(P.linear(s, f.w1, f.b1));
    pre = kernels::view_attention(qr, kv, 128);
  } else if (fdi.key0) {
    const auto kv = Products::fp32(P.linear(a, f.w0, f.b0));
    const auto k = kv.narrow(2, 0, 128), u = kv.narrow(2, 128, 256);
    pre = torch::baddbmm(u + fdi.fc_1->bias, kernels::view_attention_weights(k, k), u);
  } else {
    pre = P.linear(s, f.w1, f.b1);
  }
  return P.linear(pre.relu_(), fdi.fc_2->weight, fdi.fc_2->bias).relu_();
}

// ---- per point: the heads ----------------------------------------------------------------------

torch::Tensor Plan::density(const torch::Tensor& e) const {
  const auto& heads = *model_.heads;
  const auto& P = target_.products;
  const auto h = P.linear(Products::fp32(e).mean(1), heads.fc_3->weight, heads.fc_3->bias).relu_();
  return P.linear_fp32(h, heads.alpha_fc->weight, heads.alpha_fc->bias).squeeze(1);
}

torch::Tensor Plan::colour(const FrameCache& frame, const torch::Tensor& e,
                           const torch::Tensor& pixels, const torch::Tensor& dir_code) const {
  if (const auto* folded = std::get_if<FoldedWeights>(&frame.network))
    return colour_folded(folded->heads, e, pixels, dir_code);
  return colour_layers(e, pixels, dir_code);
}

torch::Tensor Plan::colour_layers(const torch::Tensor& e, const torch::Tensor& p,
                                  const torch::Tensor& dir_code) const {
  const auto& heads = *model_.heads;
  auto c = layer_fp32(heads.feature_fc, e);
  if (heads.rgb_res_0) c = c + affine(heads.rgb_res_0, p);  // w/o a: no residuals from p_v
  const auto d = dir_code.unsqueeze(1).expand({e.size(0), e.size(1), dir_code.size(1)});
  c = torch::relu(affine(heads.view_fc, torch::cat({c, d}, 2)));
  if (heads.rgb_res_1) c = c + affine(heads.rgb_res_1, p);
  return affine(heads.rgb_fc, torch::relu(affine(heads.fc_4, c.mean(1))));
}

// view_fc(cat(c, gamma)) = (view_fc_c . feature_fc) e + view_fc_c rgb_res_0(p) + view_fc_d gamma
// + b, with the pixel side read as one 256-channel readout [view_fc_c . rgb_res_0 ; rgb_res_1].
torch::Tensor Plan::colour_folded(const HeadsFolded& f, const torch::Tensor& e,
                                  const torch::Tensor& readout,
                                  const torch::Tensor& dir_code) const {
  const auto& heads = *model_.heads;
  const auto& P = target_.products;
  const auto direction =
      P.linear_fp32(dir_code, heads.view_fc->weight.narrow(1, 256, kDirectionEncodingDim));
  auto c = Products::fp32(P.linear(e, f.e_weight, f.e_bias)).add_(direction.unsqueeze(1));
  if (heads.rgb_res_0)  // w/o a: no readout of p_v
    c = c.add_(readout.narrow(2, 0, 128)).relu_() + readout.narrow(2, 128, 128);
  else
    c = c.relu_();
  const auto h = P.linear_fp32(c.mean(1), heads.fc_4->weight, heads.fc_4->bias).relu_();
  return P.linear_fp32(h, heads.rgb_fc->weight, heads.rgb_fc->bias);
}

// ---- the profiled plan -------------------------------------------------------------------------

using render::ScopedTimer;

EncodedViews ProfiledPlan::encode(const torch::Tensor& images) const {
  ScopedTimer timer(profile_, "encoder");
  return Plan::encode(images);
}
torch::Tensor ProfiledPlan::paint(const EncodedViews& enc, const torch::Tensor& uv,
                                  const torch::Tensor& visibility) const {
  ScopedTimer timer(profile_, "painting");
  return Plan::paint(enc, uv, visibility);
}
HumanStage ProfiledPlan::represent(const FrameInputs& in, const PaintedBody& body) const {
  ScopedTimer timer(profile_, "transhe");
  return Plan::represent(in, body);
}
PixelStage ProfiledPlan::pixels(const EncodedViews& enc, const FrameGeometry& geometry,
                                const torch::Tensor& vertices, double cull_distance,
                                const NetworkStage& network) const {
  ScopedTimer timer(profile_, "readouts");
  return Plan::pixels(enc, geometry, vertices, cull_distance, network);
}
torch::Tensor ProfiledPlan::human(const FrameCache& frame, const torch::Tensor& xs) const {
  ScopedTimer timer(profile_, "dparf");
  return Plan::human(frame, xs);
}
torch::Tensor ProfiledPlan::appearance(const FrameCache& frame, const torch::Tensor& uv) const {
  ScopedTimer timer(profile_, "sampling");
  return Plan::appearance(frame, uv);
}
torch::Tensor ProfiledPlan::fuse(const FrameCache& frame, const torch::Tensor& s,
                                 const torch::Tensor& a) const {
  ScopedTimer timer(profile_, "fdi");
  return Plan::fuse(frame, s, a);
}
torch::Tensor ProfiledPlan::density(const torch::Tensor& e) const {
  ScopedTimer timer(profile_, "heads");
  return Plan::density(e);
}
torch::Tensor ProfiledPlan::colour_pixels(const FrameCache& frame, const torch::Tensor& uv) const {
  ScopedTimer timer(profile_, "sampling");
  return Plan::colour_pixels(frame, uv);
}
torch::Tensor ProfiledPlan::colour(const FrameCache& frame, const torch::Tensor& e,
                                   const torch::Tensor& pixels,
                                   const torch::Tensor& dir_code) const {
  ScopedTimer timer(profile_, "heads");
  return Plan::colour(frame, e, pixels, dir_code);
}

}  // namespace th::model
