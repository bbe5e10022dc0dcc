#include "model/plan.hpp"

#include "geometry/camera.hpp"
#include "model/kernels/gather.hpp"
#include "model/kernels/view_attention.hpp"
#include "model/positional_encoding.hpp"
#include "model/shortcuts.hpp"
#include "model/transhuman.hpp"
#include "render/volume.hpp"

namespace th::model {

using render::ScopedTimer;

Plan::Plan(TransHumanImpl& model, const PlanTarget& target, render::Profile* profile)
    : model_(model), target_(target), profile_(profile) {
  if (model.config().fdi.appearance)
    pixel_form_ = !target.training && target.cpu_kernels ? PixelForm::windows : PixelForm::readouts;
}

const char* Plan::pixel_form() const {
  switch (pixel_form_) {
    case PixelForm::none:
      return "no pixels";
    case PixelForm::readouts:
      return "pixel readouts";
    case PixelForm::windows:
      return "readout windows";
  }
  return "";
}

// ---- per frame ----------------------------------------------------------------------------------

EncodedViews Plan::encode(const torch::Tensor& images) const {
  ScopedTimer timer(profile_, "encoder");
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
  ScopedTimer timer(profile_, "painting");
  return model_.encoder->paint(enc, uv, visibility);
}

HumanStage Plan::represent(const FrameInputs& in, const PaintedBody& body) const {
  ScopedTimer timer(profile_, "transhe");
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

FoldedWeights Plan::weights() const { return fold_weights(*model_.fdi, *model_.heads); }

PixelStage Plan::pixels(const EncodedViews& enc, const FrameGeometry& geometry,
                        const torch::Tensor& vertices, double cull_distance,
                        const FoldedWeights& network) const {
  ScopedTimer timer(profile_, "readouts");
  const auto& encoder = *model_.encoder;
  switch (pixel_form_) {
    case PixelForm::none:
      return NoPixels{};
    case PixelForm::windows:
      if (cull_distance > 0) {  // points bounded to the body's surroundings
        const auto windows = body_windows(geometry, vertices, cull_distance, enc.geometry);
        return make_window_readouts(encoder, enc, *model_.fdi, network.heads, windows);
      }
      [[fallthrough]];
    case PixelForm::readouts:
      return make_pixel_readouts(encoder, enc, *model_.fdi, network.heads);
  }
  return NoPixels{};
}

// ---- per point: the human representation -------------------------------------------------------

torch::Tensor Plan::human(const FrameCache& frame, const torch::Tensor& xs) const {
  ScopedTimer timer(profile_, "dparf");
  return model_.human->forward(frame.human, xs, target_.products);
}

// ---- per point: what sampling reads of the pixels ----------------------------------------------

torch::Tensor Plan::read_windows(const WindowReadouts& px, const WindowReadout& readout,
                                 const torch::Tensor& uv) const {
  const auto [flat, view] = PixelGeometry::point_view_rows(uv);
  const auto& g = px.enc.geometry;
  const auto [taps, inside] = px.windows.taps(flat, view, g.height, g.width);
  auto out = kernels::weighted_gather(readout.table, taps);
  if (!inside.all().item<bool>()) {  // outside the windows: the layer on p_v read from the levels
    const auto idx = (~inside).nonzero().flatten();
    const auto f = flat.index_select(0, idx), v = view.index_select(0, idx);
    const auto p = model_.encoder->sample_pixel_features(px.enc, g.stacked_level_taps(f, v),
                                                         g.image_taps(f, v));
    out.index_copy_(0, idx, torch::nn::functional::linear(p, readout.weight, readout.layer_bias));
  }
  return out.view({uv.size(0), uv.size(1), -1});
}

template <class Pick>
torch::Tensor Plan::read_pixels(const PixelStage& stage, const torch::Tensor& uv, Pick pick) const {
  ScopedTimer timer(profile_, "sampling");
  if (const auto* px = std::get_if<PixelReadouts>(&stage)) {
    const auto [flat, view] = PixelGeometry::point_view_rows(uv);
    return pick(*px)
        .sample(px->geometry.stacked_level_taps(flat, view), px->geometry.image_taps(flat, view))
        .view({uv.size(0), uv.size(1), -1});
  }
  if (const auto* px = std::get_if<WindowReadouts>(&stage)) return read_windows(*px, pick(*px), uv);
  return {};  // NoPixels
}

torch::Tensor Plan::colour_pixels(const FrameCache& frame, const torch::Tensor& uv) const {
  return read_pixels(
      frame.pixels, uv, [](const auto& px) -> const auto& { return px.color; });
}

torch::Tensor Plan::appearance(const FrameCache& frame, const torch::Tensor& uv) const {
  return read_pixels(
      frame.pixels, uv, [](const auto& px) -> const auto& { return px.alpha; });
}

// ---- per point: FDI ----------------------------------------------------------------------------

// Folded weights (METHOD 9): fc_1 folded into the value projections, each key projection sharing
// one product with its value projection; fc_1's bias joins the query side.
torch::Tensor Plan::fuse(const FrameCache& frame, const torch::Tensor& s,
                         const torch::Tensor& a) const {
  ScopedTimer timer(profile_, "fdi");
  const auto& f = frame.network.fdi;
  const auto& P = target_.products;
  const auto& fdi = *model_.fdi;
  const int64_t d = fdi.key0 ? fdi.key0->weight.size(0) : 0;  // the attention's key width
  torch::Tensor pre;                                          // fc_1's output before its ReLU
  if (fdi.key0 && fdi.key1) {
    // (N, V, d + 256) each; the attention kernel takes fp32
    const auto kv = Products::fp32(P.linear(a, f.w0, f.b0));
    const auto qr = Products::fp32(P.linear(s, f.w1, f.b1));
    pre = kernels::view_attention(qr, kv, d);
  } else if (fdi.key0) {  // "w/o h": self-attention of the appearance features
    const auto kv = Products::fp32(P.linear(a, f.w0, f.b0));
    const auto k = kv.narrow(2, 0, d), u = kv.narrow(2, d, kv.size(2) - d);
    pre = torch::baddbmm(u + fdi.fc_1->bias, kernels::view_attention_weights(k, k), u);
  } else {  // "w/o a": fc_1(value1(s_v))
    pre = P.linear(s, f.w1, f.b1);
  }
  return P.linear(pre.relu_(), fdi.fc_2->weight, fdi.fc_2->bias).relu_();
}

// ---- per point: the heads ----------------------------------------------------------------------

torch::Tensor Plan::density(const torch::Tensor& e) const {
  ScopedTimer timer(profile_, "heads");
  const auto& heads = *model_.heads;
  const auto& P = target_.products;
  const auto h = P.linear(Products::fp32(e).mean(1), heads.fc_3->weight, heads.fc_3->bias).relu_();
  return P.linear_fp32(h, heads.alpha_fc->weight, heads.alpha_fc->bias).squeeze(1);
}

// view_fc(cat(c, gamma)) = (view_fc_c . feature_fc) e + view_fc_c rgb_res_0(p) + view_fc_d gamma
// + b, with the pixel side read as one 256-channel readout [view_fc_c . rgb_res_0 ; rgb_res_1].
torch::Tensor Plan::colour(const FrameCache& frame, const torch::Tensor& e,
                           const torch::Tensor& readout, const torch::Tensor& dir_code) const {
  ScopedTimer timer(profile_, "heads");
  const auto& f = frame.network.heads;
  const auto& heads = *model_.heads;
  const auto& P = target_.products;
  const auto direction =
      P.linear_fp32(dir_code, heads.view_fc->weight.narrow(1, 256, kDirectionEncodingDim));
  auto c = Products::fp32(P.linear(e, f.e_weight, f.e_bias)).add_(direction.unsqueeze(1));
  if (heads.rgb_res_0) {  // w/o a: no readout of p_v
    const int64_t half = readout.size(2) / 2;
    c = c.add_(readout.narrow(2, 0, half)).relu_() + readout.narrow(2, half, half);
  } else {
    c = c.relu_();
  }
  const auto h = P.linear_fp32(c.mean(1), heads.fc_4->weight, heads.fc_4->bias).relu_();
  return P.linear_fp32(h, heads.rgb_fc->weight, heads.rgb_fc->bias);
}

}  // namespace th::model
