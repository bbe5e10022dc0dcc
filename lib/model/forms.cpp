#include "model/forms.hpp"

#include "model/shortcuts.hpp"

namespace th::model {
namespace {

namespace F = torch::nn::functional;

// ---- pixel forms ------------------------------------------------------------------------------

class NoPixelForm final : public PixelForm {
 public:
  PixelStage prepare(const PixelFrame&, const NetworkStage&) const override { return NoPixels{}; }
  torch::Tensor appearance(const PixelStage&, const torch::Tensor&) const override { return {}; }
  torch::Tensor colour(const PixelStage&, const torch::Tensor&) const override { return {}; }
};

// p_v materialised at full resolution and grid-sampled: the reference's computation.
class PixelMapForm final : public PixelForm {
 public:
  PixelMapForm(Encoder encoder, FDI fdi) : encoder_(std::move(encoder)), fdi_(std::move(fdi)) {}
  PixelStage prepare(const PixelFrame& f, const NetworkStage&) const override {
    return PixelMap{encoder_->pixel_features(f.enc)};
  }
  torch::Tensor appearance(const PixelStage& stage, const torch::Tensor& uv) const override {
    return F::linear(colour(stage, uv), fdi_->alpha_res_0->weight, fdi_->alpha_res_0->bias);
  }
  torch::Tensor colour(const PixelStage& stage, const torch::Tensor& uv) const override {
    return grid_sample_pixels(std::get<PixelMap>(stage).pixel, uv);
  }

 private:
  Encoder encoder_;
  FDI fdi_;
};

// p_v sampled exactly from the ResNet levels and the images (encoder.fast_sampling).
class PixelLevelsForm final : public PixelForm {
 public:
  PixelLevelsForm(Encoder encoder, FDI fdi) : encoder_(std::move(encoder)), fdi_(std::move(fdi)) {}
  PixelStage prepare(const PixelFrame& f, const NetworkStage&) const override {
    return PixelLevels{f.enc};
  }
  torch::Tensor appearance(const PixelStage& stage, const torch::Tensor& uv) const override {
    return F::linear(colour(stage, uv), fdi_->alpha_res_0->weight, fdi_->alpha_res_0->bias);
  }
  torch::Tensor colour(const PixelStage& stage, const torch::Tensor& uv) const override {
    return encoder_->sample_pixel_features(std::get<PixelLevels>(stage).enc, uv);
  }

 private:
  Encoder encoder_;
  FDI fdi_;
};

// METHOD 9: per-level readouts of alpha_res_0 and of the colour head's folded readout; at
// inference on CPU, with a culling distance, their window form around the body.
class ReadoutForm final : public PixelForm {
 public:
  ReadoutForm(Encoder encoder, FDI fdi, bool windows)
      : encoder_(std::move(encoder)), fdi_(std::move(fdi)), windows_(windows) {}

  PixelStage prepare(const PixelFrame& f, const NetworkStage& network) const override {
    const auto& heads = std::get<FoldedWeights>(network).heads;
    if (windows_ && !torch::GradMode::is_enabled() && f.enc.images.device().is_cpu() &&
        f.cull_distance > 0) {
      const auto windows = body_windows(f.geometry, f.vertices, f.cull_distance, f.enc.geometry);
      return make_window_readouts(*encoder_, f.enc, *fdi_, heads, windows);
    }
    return make_pixel_readouts(*encoder_, f.enc, *fdi_, heads);
  }
  torch::Tensor appearance(const PixelStage& stage, const torch::Tensor& uv) const override {
    if (const auto* w = std::get_if<WindowReadouts>(&stage)) return read(*w, w->alpha, uv);
    const auto& px = std::get<PixelReadouts>(stage);
    return read(px, px.alpha, uv);
  }
  torch::Tensor colour(const PixelStage& stage, const torch::Tensor& uv) const override {
    if (const auto* w = std::get_if<WindowReadouts>(&stage)) return read(*w, w->color, uv);
    const auto& px = std::get<PixelReadouts>(stage);
    return read(px, px.color, uv);
  }

 private:
  static torch::Tensor read(const PixelReadouts& px, const PixelReadout& readout,
                            const torch::Tensor& uv) {
    const auto [flat, view] = PixelGeometry::point_view_rows(uv);
    return readout
        .sample(px.geometry.stacked_level_taps(flat, view), px.geometry.image_taps(flat, view))
        .view({uv.size(0), uv.size(1), -1});
  }
  torch::Tensor read(const WindowReadouts& px, const WindowReadout& readout,
                     const torch::Tensor& uv) const {
    const auto [flat, view] = PixelGeometry::point_view_rows(uv);
    const auto& g = px.levels.enc.geometry;
    const auto [taps, inside] = px.windows.taps(flat, view, g.height, g.width);
    auto out = weighted_gather(readout.table, taps);
    if (!inside.all().item<bool>()) {  // outside the windows: the layer on p_v read from the levels
      const auto idx = (~inside).nonzero().flatten();
      const auto f = flat.index_select(0, idx), v = view.index_select(0, idx);
      const auto p = encoder_->sample_pixel_features(px.levels.enc, g.stacked_level_taps(f, v),
                                                     g.image_taps(f, v));
      out.index_copy_(0, idx, F::linear(p, readout.weight, readout.layer_bias));
    }
    return out.view({uv.size(0), uv.size(1), -1});
  }

  Encoder encoder_;
  FDI fdi_;
  bool windows_;
};

// ---- network forms ----------------------------------------------------------------------------

class LayerNetwork final : public NetworkForm {
 public:
  LayerNetwork(FDI fdi, Heads heads) : fdi_(std::move(fdi)), heads_(std::move(heads)) {}
  // (The modules' forward passes are not const.)
  NetworkStage prepare() const override { return LayerWeights{}; }
  torch::Tensor trunk(const NetworkStage&, const torch::Tensor& s, const torch::Tensor& a,
                      const Products& products) const override {
    return fdi_->forward(s, a, products);
  }
  torch::Tensor colour(const NetworkStage&, const torch::Tensor& e, const torch::Tensor& pixels,
                       const torch::Tensor& dir_code, const Products& products) const override {
    return heads_->color(e, pixels, dir_code, products);
  }

 private:
  mutable FDI fdi_;
  mutable Heads heads_;
};

class FoldedNetwork final : public NetworkForm {
 public:
  FoldedNetwork(FDI fdi, Heads heads) : fdi_(std::move(fdi)), heads_(std::move(heads)) {}
  NetworkStage prepare() const override { return fold_weights(*fdi_, *heads_); }
  torch::Tensor trunk(const NetworkStage& stage, const torch::Tensor& s, const torch::Tensor& a,
                      const Products& products) const override {
    return fdi_->forward_folded(std::get<FoldedWeights>(stage).fdi, s, a, products);
  }
  torch::Tensor colour(const NetworkStage& stage, const torch::Tensor& e,
                       const torch::Tensor& pixels, const torch::Tensor& dir_code,
                       const Products& products) const override {
    return heads_->color_folded(std::get<FoldedWeights>(stage).heads, e, pixels, dir_code,
                                products);
  }

 private:
  mutable FDI fdi_;
  mutable Heads heads_;
};

}  // namespace

std::unique_ptr<PixelForm> make_pixel_form(const ModelConfig& config, Encoder encoder, FDI fdi) {
  if (!config.fdi.appearance) return std::make_unique<NoPixelForm>();
  if (config.exact_shortcuts)
    return std::make_unique<ReadoutForm>(encoder, fdi, config.readout_windows);
  if (config.encoder.fast_sampling) return std::make_unique<PixelLevelsForm>(encoder, fdi);
  return std::make_unique<PixelMapForm>(encoder, fdi);
}

std::unique_ptr<NetworkForm> make_network_form(const ModelConfig& config, FDI fdi, Heads heads) {
  if (config.exact_shortcuts) return std::make_unique<FoldedNetwork>(fdi, heads);
  return std::make_unique<LayerNetwork>(fdi, heads);
}

}  // namespace th::model
