// The definition of the network (METHOD 3), in the paper's order: prepare() once per frame,
// forward() and its variants per chunk of points.
#include "model/transhuman.hpp"

#include <spdlog/spdlog.h>

#include "geometry/camera.hpp"
#include "model/kernels/encoding.hpp"
#include "model/pixels.hpp"
#include "render/body_distance.hpp"

namespace th::model {

using render::ScopedTimer;

TransHumanImpl::TransHumanImpl(const ModelConfig& config) : config_(config) {
  encoder =
      register_module("encoder", Encoder(config.encoder, config.fdi.raw_rgb, config.transhe.dim));
  if (!config.encoder.pretrained.empty()) {
    load_pretrained_encoder(*encoder, config.encoder.pretrained);
    spdlog::info("encoder: ImageNet ResNet-18 weights from {}", config.encoder.pretrained);
  } else {
    spdlog::info("encoder: random initialisation (model.encoder.pretrained is empty)");
  }
  if (config.fdi.human) human = register_module("human", make_human_representation(config));
  fdi = register_module("fdi", FDI(config.fdi, encoder->pixel_channels()));
  heads = register_module("heads", Heads(config.fdi.appearance, encoder->pixel_channels()));
}

// ---- once per frame (METHOD 3.1-3.2) ------------------------------------------------------------

FrameCache TransHumanImpl::prepare(const FrameInputs& in, double cull_distance) {
  in.check();
  FrameCache frame;
  const auto opts = in.ref_images.options();
  auto& geo = frame.geometry;
  geo.K = in.K.to(opts);
  geo.R = in.R.to(opts);
  geo.T = in.T.to(opts).reshape({-1, 3, 1});
  geo.Rh = in.Rh.to(opts);
  geo.Th = in.Th.to(opts).reshape({3});
  if (cull_distance > 0)
    geo.body = std::make_shared<render::BodyDistance>(in.vertices, cull_distance);

  // 3.1 The encoder: the ResNet levels L0, L1, L2 of the reference images. The pixel feature p_v
  // is their upsampled concatenation with a convolution of the image; it is read, never formed.
  EncodedViews enc;
  {
    ScopedTimer timer(profile_, "encoder");
    FrameAutocast autocast(products_, opts.device());
    enc = encoder->forward(in.ref_images);
  }
  for (auto& level : enc.levels) level = Products::fp32(level);
  frame.network = {fdi->fold(), heads->fold()};  // the per-point layers, folded (METHOD 9)

  if (human) {
    // 3.1 Painting: F_v, the holder features at the vertices' projections, zero where a vertex is
    // invisible in a view.
    PaintedBody body;
    const auto vertices = in.vertices.to(opts);
    {
      ScopedTimer timer(profile_, "painting");
      const auto uv = geometry::project_views(vertices, geo.K, geo.R, geo.T);
      body.features = encoder->paint(enc, uv, in.visibility);
    }
    body.xs_vertices = torch::mm(vertices - geo.Th, geo.Rh);
    // 3.2 TransHE's tokens T_v and DPaRF's token frames (Oc, Rc), or the SPC baseline's volume.
    ScopedTimer timer(profile_, "transhe");
    {
      FrameAutocast autocast(products_, opts.device());
      frame.human = human->prepare(in, body);
    }
    std::visit(
        [](auto& stage) {
          stage.visit([](torch::Tensor& t, torch::Tensor*) {
            if (t.defined()) t = Products::fp32(t);
          });
        },
        frame.human);
  }
  // What the per-point stages read of p_v: alpha_res_0 and the colour head's readout.
  ScopedTimer timer(profile_, "readouts");
  frame.pixels = prepare_pixels(*encoder, enc, *fdi, frame.network.heads, geo, in.vertices,
                                cull_distance, products_.between(enc.images.scalar_type()));
  return frame;
}

// ---- per chunk of points (METHOD 3.3-3.4) -------------------------------------------------------

TransHumanImpl::Trunk TransHumanImpl::trunk(const FrameCache& frame, const torch::Tensor& pts) {
  TORCH_CHECK(pts.dim() == 2 && pts.size(1) == 3, "pts must be (N, 3), got ", pts.sizes());
  const auto& geo = frame.geometry;
  // 3.3 s_v: the human representation of every reference view at the points (SMPL frame).
  torch::Tensor s;
  if (human) {
    ScopedTimer timer(profile_, "dparf");
    s = human->forward(frame.human, torch::mm(pts - geo.Th, geo.Rh), products_);
  }
  // 3.4 a_v = relu(alpha_res_0(p_v)) at the points' projections uv into the reference views, in
  // the type FDI's products read.
  const auto uv = geometry::project_views(pts, geo.K, geo.R, geo.T).permute({1, 0, 2}).contiguous();
  torch::Tensor a;
  {
    ScopedTimer timer(profile_, "sampling");
    a = sample_pixels(frame.pixels, *encoder, uv, PixelLayer::appearance, true,
                      products_.between(uv.scalar_type()));
  }
  // 3.4 FDI: e_v from the views' attention of s_v over a_v.
  ScopedTimer timer(profile_, "fdi");
  return {fdi->forward(frame.network.fdi, s, a, products_), uv};
}

// 3.4 The density head: sigma_raw from the mean of e_v over the views.
torch::Tensor TransHumanImpl::density(const Trunk& t) {
  ScopedTimer timer(profile_, "heads");
  return heads->density(t.e, products_);
}

// What the colour head reads of p_v at the points (rgb_res_0, rgb_res_1, folded).
torch::Tensor TransHumanImpl::colour_readout(const FrameCache& frame, const Trunk& t) {
  ScopedTimer timer(profile_, "sampling");
  return sample_pixels(frame.pixels, *encoder, t.uv, PixelLayer::colour);
}

// 3.4 The colour head: rgb logits from e_v, p_v and the view direction's code gamma(d).
torch::Tensor TransHumanImpl::colour(const FrameCache& frame, const Trunk& t,
                                     const torch::Tensor& readout, const torch::Tensor& dirs) {
  const auto code = kernels::direction_encoding(dirs / dirs.norm(2, -1, true));
  ScopedTimer timer(profile_, "heads");
  return heads->colour(frame.network.heads, t.e, readout, code, products_);
}

torch::Tensor TransHumanImpl::forward(const FrameCache& frame, const torch::Tensor& pts,
                                      const torch::Tensor& dirs) {
  const auto t = trunk(frame, pts);
  const auto sigma = density(t);
  const auto rgb = colour(frame, t, colour_readout(frame, t), dirs);
  return torch::cat({rgb, sigma.unsqueeze(1)}, 1);
}

torch::Tensor TransHumanImpl::density(const FrameCache& frame, const torch::Tensor& pts) {
  return density(trunk(frame, pts));
}

TransHumanImpl::DirectionalRaw TransHumanImpl::forward_directions(const FrameCache& frame,
                                                                  const torch::Tensor& pts,
                                                                  const torch::Tensor& dirs) {
  TORCH_CHECK(dirs.dim() == 3 && dirs.size(1) == pts.size(0) && dirs.size(2) == 3,
              "forward_directions: directions must be (K, ", pts.size(0), ", 3), got ",
              dirs.sizes());
  const auto t = trunk(frame, pts);
  return {density(t), colour(frame, t, colour_readout(frame, t), dirs.to(pts.options()))};
}

torch::Tensor TransHumanImpl::forward_density_first(const FrameCache& frame,
                                                    const torch::Tensor& pts,
                                                    const torch::Tensor& dirs) {
  const auto t = trunk(frame, pts);
  const auto sigma = density(t);
  const auto idx = (sigma > 0).nonzero().flatten();
  // Every point has density (a translucent model): colour for all rows, without copying the
  // trunk's (N, V, 256) output row by row.
  if (idx.size(0) == pts.size(0))
    return torch::cat({colour(frame, t, colour_readout(frame, t), dirs), sigma.unsqueeze(1)}, 1);
  auto raw = torch::zeros({pts.size(0), 4}, sigma.options());
  raw.select(1, 3).copy_(sigma);
  if (idx.size(0) == 0) return raw;
  const Trunk sub{t.e.index_select(0, idx), t.uv.index_select(0, idx)};
  const auto rgb = colour(frame, sub, colour_readout(frame, sub), dirs.index_select(0, idx));
  raw.index_copy_(0, idx, torch::cat({rgb, sigma.index_select(0, idx).unsqueeze(1)}, 1));
  return raw;
}

std::vector<ParameterCount> parameter_counts(const TransHumanImpl& model) {
  std::vector<ParameterCount> out{{"encoder (ResNet-18 to layer2)", 0}, {"reduction + colour", 0}};
  const bool spc = model.config().representation == Representation::spc_trilinear;
  if (model.human) out.push_back({spc ? "SPC network" : "ViT", 0});
  out.push_back({"heads (fc_0, FDI, density, colour)", 0});
  auto find = [&](const std::string& name) -> int64_t& {
    for (auto& c : out)
      if (c.module == name) return c.count;
    throw std::logic_error("no parameter group " + name);
  };
  for (const auto& p : model.named_parameters()) {
    const auto& k = p.key();
    auto starts = [&](const char* prefix) { return k.rfind(prefix, 0) == 0; };
    int64_t* slot;
    if (starts("encoder.model."))
      slot = &find("encoder (ResNet-18 to layer2)");
    else if (starts("encoder."))
      slot = &find("reduction + colour");
    else if (starts("human.ViT."))
      slot = &find("ViT");
    else if (starts("human.embed.") || starts("human.conv."))
      slot = &find("SPC network");
    else
      slot = &find("heads (fc_0, FDI, density, colour)");
    *slot += p.value().numel();
  }
  int64_t total = 0;
  for (const auto& c : out) total += c.count;
  out.push_back({"total", total});
  return out;
}

}  // namespace th::model
