#include "model/pixels.hpp"

#include <optional>

#include "geometry/camera.hpp"
#include "model/encoder.hpp"
#include "model/fdi.hpp"
#include "model/heads.hpp"
#include "model/kernels/forms.hpp"
#include "model/kernels/gather.hpp"
#include "render/chunks.hpp"
#include "render/volume.hpp"

namespace th::model {

namespace {

// The window form of a readout: its values at every window pixel, read from its level table
// and stored in `type` (bf16: rounded once, to nearest even).
WindowReadout to_window(const PixelReadout& r, const torch::Tensor& weight,
                        const torch::Tensor& bias, const PixelWindows& windows,
                        const torch::Tensor& uv, const torch::Tensor& view, const PixelGeometry& g,
                        c10::ScalarType type) {
  constexpr int64_t kChunk = 65536;  // window pixels per step: bounds the taps' memory
  WindowReadout w{torch::empty({windows.rows(), r.table.size(1)}, r.table.options().dtype(type)),
                  weight, bias};
  render::for_each_chunk(windows.rows(), kChunk, [&](int64_t b, int64_t e) {
    const auto u = uv.slice(0, b, e), v = view.slice(0, b, e);
    w.table.slice(0, b, e).copy_(r.sample(g.stacked_level_taps(u, v), g.image_taps(u, v)));
  });
  return w;
}

}  // namespace

PixelStage prepare_pixels(const EncoderImpl& encoder, const EncodedViews& enc, const FDIImpl& fdi,
                          const HeadsFolded& heads, const FrameGeometry& geometry,
                          const torch::Tensor& vertices, double cull_distance,
                          c10::ScalarType window_type) {
  if (!fdi.alpha_res_0) return NoPixels{};
  const auto& alpha = *fdi.alpha_res_0;
  if (torch::GradMode::is_enabled() || !kernels::cpu_kernels(enc.images.device()) ||
      cull_distance <= 0) {
    PixelReadouts px;
    px.geometry = enc.geometry;
    px.alpha = encoder.make_readout(enc, alpha.weight, alpha.bias);
    px.color = encoder.make_readout(enc, heads.readout_weight, heads.readout_bias);
    px.color.image_table = px.alpha.image_table;  // one copy of the raw images
    return px;
  }
  WindowReadouts px;
  px.windows = body_windows(geometry, vertices, cull_distance, enc.geometry);
  const auto [uv, view] = px.windows.pixels(enc.images.options());
  // One readout at a time, so that a single level table exists at any moment; of each table
  // only the rows the windows read.
  const auto footprint = px.windows.footprint(enc.geometry, uv.options());
  px.alpha = to_window(encoder.make_readout(enc, alpha.weight, alpha.bias, &footprint),
                       alpha.weight, alpha.bias, px.windows, uv, view, enc.geometry, window_type);
  px.color = to_window(
      encoder.make_readout(enc, heads.readout_weight, heads.readout_bias, &footprint),
      heads.readout_weight, heads.readout_bias, px.windows, uv, view, enc.geometry, window_type);
  px.enc = enc;  // for points outside the windows
  return px;
}

namespace {

torch::Tensor read_windows(const WindowReadouts& px, const WindowReadout& readout,
                           const EncoderImpl& encoder, const torch::Tensor& uv,
                           const kernels::GatherEpilogue& epilogue) {
  std::optional<render::ScopedTimer> timer(std::in_place, "sampling.taps");
  const auto [flat, view] = PixelGeometry::point_view_rows(uv);
  const auto& g = px.enc.geometry;
  const auto [taps, inside] = px.windows.taps(flat, view, g.height, g.width);
  timer.emplace("sampling.gather");
  auto out = kernels::weighted_gather(readout.table, taps, {}, epilogue);
  timer.emplace("sampling.outside");
  if (!inside.all().item<bool>()) {  // outside the windows: the layer on p_v read from the levels
    const auto idx = (~inside).nonzero().flatten();
    const auto f = flat.index_select(0, idx), v = view.index_select(0, idx);
    const auto p =
        encoder.sample_pixel_features(px.enc, g.stacked_level_taps(f, v), g.image_taps(f, v));
    auto rows = torch::nn::functional::linear(p, readout.weight, readout.layer_bias);
    if (epilogue.relu) rows.relu_();
    out.index_copy_(0, idx, rows.to(out.scalar_type()));
  }
  return out.view({uv.size(0), uv.size(1), -1});
}

}  // namespace

torch::Tensor sample_pixels(const PixelStage& stage, const EncoderImpl& encoder,
                            const torch::Tensor& uv, PixelLayer layer, bool relu,
                            c10::optional<c10::ScalarType> dtype) {
  const bool alpha = layer == PixelLayer::appearance;
  if (const auto* px = std::get_if<PixelReadouts>(&stage)) {
    std::optional<render::ScopedTimer> timer(std::in_place, "sampling.taps");
    const auto [flat, view] = PixelGeometry::point_view_rows(uv);
    const auto level_taps = px->geometry.stacked_level_taps(flat, view);
    const auto image_taps = px->geometry.image_taps(flat, view);
    timer.emplace("sampling.gather");
    auto out = (alpha ? px->alpha : px->color)
                   .sample(level_taps, image_taps)
                   .view({uv.size(0), uv.size(1), -1});
    if (relu) out = out.relu();
    return dtype ? out.to(*dtype) : out;
  }
  if (const auto* px = std::get_if<WindowReadouts>(&stage))
    return read_windows(*px, alpha ? px->alpha : px->color, encoder, uv, {{}, relu, dtype});
  return {};  // NoPixels
}

PixelWindows body_windows(const FrameGeometry& geo, const torch::Tensor& vertices, double distance,
                          const PixelGeometry& g) {
  TORCH_CHECK(vertices.dim() == 2 && vertices.size(1) == 3,
              "body_windows: vertices must be (Nv, 3), got ", vertices.sizes());
  const auto opts = geo.K.options();
  auto signs = torch::tensor({-1.0, 1.0}, opts);
  const auto grid = torch::meshgrid({signs, signs, signs}, "ij");
  signs = torch::stack({grid[0].flatten(), grid[1].flatten(), grid[2].flatten()}, 1);  // (8, 3)
  const auto corners = (vertices.to(opts).unsqueeze(1) + distance * signs).reshape({-1, 3});
  const auto depth =
      (torch::matmul(corners.unsqueeze(0), geo.R.transpose(1, 2)) + geo.T.reshape({-1, 1, 3}))
          .select(2, 2);
  const auto uv = geometry::project_views(corners, geo.K, geo.R, geo.T);  // (V, 8 Nv, 2)
  PixelWindows w;
  int64_t offset = 0;
  for (int64_t v = 0; v < g.views; ++v) {
    int64_t x0 = 0, y0 = 0, x1 = g.width, y1 = g.height;
    const bool in_front = depth[v].min().item<double>() > 0 && uv[v].isfinite().all().item<bool>();
    if (in_front && corners.size(0) > 0) {
      const auto lo = std::get<0>(uv[v].min(0)), hi = std::get<0>(uv[v].max(0));
      auto clampi = [](double x, int64_t n) {
        return std::min<int64_t>(std::max<double>(x, 0), n);
      };
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
