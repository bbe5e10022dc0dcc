#include "model/network.hpp"

#include <cmath>
#include <vector>

#include "core/error.hpp"
#include "model/spc.hpp"
#include "model/transhe.hpp"

namespace th::model {
namespace {

namespace F = torch::nn::functional;
using torch::Tensor;

Tensor linear(const torch::nn::Linear& layer, const Tensor& x) {
  return F::linear(x, layer->weight, layer->bias);
}

template <class Conv>
Tensor conv2d(const Conv& c, const Tensor& x) {
  return F::conv2d(
      x, c.weight,
      F::Conv2dFuncOptions().bias(c.bias).stride(c.options.stride()).padding(c.options.padding()));
}

// As BatchNormImpl::forward, without updating the running statistics.
Tensor batch_norm(const BatchNormImpl& bn, const Tensor& x) {
  const bool batch = bn.is_training() || bn.batch_stats_at_inference;
  if (bn.is_training() && bn.sync)
    fail(
        "config key 'train.sync_batchnorm': the plain network pass (model/network.hpp) has no "
        "synchronised BatchNorm");
  return torch::batch_norm(x, bn.weight, bn.bias, batch ? Tensor() : bn.running_mean,
                           batch ? Tensor() : bn.running_var, batch, 0.1, 1e-5, false);
}

// Written apart from the running code's helpers (positional_encoding, cluster_mean, the camera
// projection), so that a bug in one of those does not pass on both sides of the equality tests.

// sin(x f + phase) for f = fl32(pi) 2^j, j < num_freqs, phase 0 (sin) and fl32(pi/2) (cos):
// (M, D) -> (M, 2 num_freqs D), [sin(f0 x), cos(f0 x), sin(f1 x), ...] (METHOD 3.2, 3.3). `fused`
// rounds x f + phase once: float64 holds the product of two floats exactly, so the sum is rounded
// there and then to the input's type [parity: the reference's addcmul].
Tensor sincos(const Tensor& x, int64_t num_freqs, bool fused) {
  // f0 f0 f1 f1 ..., 0 pi/2 0 pi/2 ..., in x's type (pi rounded to float32 first for float32)
  const bool f64 = x.scalar_type() == torch::kDouble;
  const double pi = f64 ? M_PI : static_cast<double>(static_cast<float>(M_PI));
  std::vector<double> freqs, phases;
  for (int64_t j = 0; j < num_freqs; ++j)
    for (const double phase : {0.0, M_PI / 2}) {
      freqs.push_back(pi * std::ldexp(1.0, static_cast<int>(j)));
      phases.push_back(phase);
    }
  const auto column = [&](const std::vector<double>& v) {
    return torch::tensor(v, torch::kDouble).to(x.options()).view({1, -1, 1});
  };
  const auto f = column(freqs), phase = column(phases);
  if (!fused) return torch::sin(x.unsqueeze(1) * f + phase).flatten(1);
  const auto d = torch::kDouble;
  const auto arg = torch::addcmul(phase.to(d), x.to(d).unsqueeze(1), f.to(d)).to(x.scalar_type());
  return torch::sin(arg).flatten(1);
}

// Pinhole projection of points (N, 3) into the views (K, R, T) -> pixel coordinates (N, V, 2).
Tensor project(const Tensor& points, const Tensor& K, const Tensor& R, const Tensor& T) {
  const auto cam = torch::einsum("vij,nj->nvi", {R, points}) + T.reshape({1, -1, 3});
  const auto img = torch::einsum("vij,nvj->nvi", {K, cam});
  return img.narrow(2, 0, 2) / img.narrow(2, 2, 1);
}

// NeRF's view-direction embedder gamma(d), 4 octaves: [d, sin d, cos d, ..., sin 8d, cos 8d].
Tensor gamma_of(const Tensor& d) {
  std::vector<Tensor> parts{d};
  for (const double f : {1.0, 2.0, 4.0, 8.0})
    parts.insert(parts.end(), {torch::sin(d * f), torch::cos(d * f)});
  return torch::cat(parts, 1);
}

// ---- METHOD 3.1: image encoder and painting -----------------------------------------------------

Tensor basic_block(const BasicBlockImpl& b, const Tensor& x) {
  const auto y =
      batch_norm(*b.bn2, conv2d(*b.conv2, torch::relu(batch_norm(*b.bn1, conv2d(*b.conv1, x)))));
  const auto skip = b.downsample
                        ? batch_norm(*b.downsample->ptr<BatchNormImpl>(1),
                                     conv2d(*b.downsample->ptr<torch::nn::Conv2dImpl>(0), x))
                        : x;
  return torch::relu(y + skip);
}

Tensor res_layer(const torch::nn::Sequential& layer, Tensor x) {
  for (size_t i = 0; i < layer->size(); ++i) x = basic_block(*layer->ptr<BasicBlockImpl>(i), x);
  return x;
}

// p_v: (V, 3, H, W) images -> (V, 384, H, W), or 256 channels w/o RGB.
Tensor pixel_features(const EncoderImpl& encoder, const Tensor& images) {
  const auto& resnet = *encoder.model;
  const auto L0 = torch::relu(batch_norm(*resnet.bn1, conv2d(*resnet.conv1, images)));
  const auto L1 =
      res_layer(resnet.layer1, F::max_pool2d(L0, F::MaxPool2dFuncOptions(3).stride(2).padding(1)));
  const auto L2 = res_layer(resnet.layer2, L1);
  return pixel_feature_map(encoder, {L0, L1, L2}, images);
}

// ---- METHOD 3.2: TransHE ------------------------------------------------------------------------

Tensor vit(const TransHEImpl& t, Tensor x) {
  const auto norm = [](const torch::nn::LayerNorm& n, const Tensor& y) {
    return F::layer_norm(y, F::LayerNormFuncOptions(n->options.normalized_shape())
                                .weight(n->weight)
                                .bias(n->bias)
                                .eps(n->options.eps()));
  };
  const int64_t V = x.size(0), Nt = x.size(1), C = x.size(2), heads = t.config.heads;
  for (const auto& module : *t.blocks) {
    const auto& block = *module->as<BlockImpl>();
    const auto qkv = linear(block.attn->qkv, norm(block.norm1, x))
                         .view({V, Nt, 3, heads, C / heads})
                         .permute({2, 0, 3, 1, 4});
    const auto attn = torch::softmax(
        torch::matmul(qkv[0], qkv[1].transpose(-2, -1)) / std::sqrt(double(C / heads)), -1);
    x = x +
        linear(block.attn->proj, torch::matmul(attn, qkv[2]).transpose(1, 2).reshape({V, Nt, C}));
    x = x + linear(block.mlp->fc2, torch::gelu(linear(block.mlp->fc1, norm(block.norm2, x))));
  }
  return norm(t.norm, x);
}

// The tokens T_v of the non-empty clusters and their DPaRF frames (Oc, Rc).
struct Tokens {
  Tensor T, Oc, Rc;  // (V, Nt, 192), (Nt, 3), (Nt, 3, 3)
};

Tokens transhe(const TokenFieldsImpl& human, const ModelConfig& cfg, const FrameInputs& in,
               const Tensor& F_v, const Tensor& xs_vertices) {
  const auto labels = in.labels.to(F_v.device());
  const int64_t nt = in.num_tokens > 0 ? in.num_tokens : labels.max().item<int64_t>() + 1;
  // Per-cluster means over the vertices (dim -2) as products with the one-hot membership
  // (Nv, nt); clusters without vertices (grid groupings) have no token.
  const auto member = F::one_hot(labels, nt);
  const auto keep = member.sum(0).nonzero().flatten();
  const auto mean = [&](const Tensor& values, const Tensor& weights = {}) {
    const auto m = member.to(values.scalar_type());
    const auto w = weights.defined() ? weights.to(values.scalar_type())
                                     : torch::ones({values.size(-2)}, values.options());
    const auto sums = torch::matmul(m.t(), values * w.unsqueeze(-1));  // (..., nt, C)
    const auto counts = torch::matmul(w, m).unsqueeze(-1);             // (..., nt, 1)
    return (sums / counts.clamp_min(1)).index_select(-2, keep);
  };
  // tok_v(c): the mean over all vertices of c, invisible zeros included [parity], or over the
  // visible ones (grouping.mean_over).
  const bool visible = cfg.grouping.mean_over == MeanOver::visible;
  const auto tok = mean(F_v, visible ? in.visibility.to(F_v.device()) : Tensor());  // (V, Nt, 192)
  Tokens t;
  t.T = tok;
  if (cfg.transhe.enabled) {
    // P_c from the canonical body in float64 [parity], or from the posed body (transhe.position).
    const auto& body =
        cfg.transhe.position == TokenPosition::observation ? xs_vertices : in.canonical;
    const double s = cfg.transhe.pe_scale;
    const auto P = ((((mean(body.to(F_v.device(), torch::kDouble)) + s) / (2 * s)) - 0.5) * 2)
                       .to(F_v.scalar_type());
    const auto PE = sincos(P, cfg.transhe.pe_freqs, cfg.transhe.pe_rounding == PeRounding::fused);
    t.T = vit(*human.vit, tok + PE.unsqueeze(0));
  }
  t.Oc = mean(xs_vertices);
  t.Rc = mean(in.A.to(xs_vertices.device(), xs_vertices.scalar_type()).reshape({-1, 9}))
             .view({-1, 3, 3});
  if (t.T.size(1) < cfg.dparf.nk)
    fail("the frame has ", t.T.size(1),
         " non-empty tokens, fewer than model.dparf.nk = ", cfg.dparf.nk);
  return t;
}

// ---- METHOD 3.3: DPaRF, and the SPC baseline ----------------------------------------------------

// xs: (N, 3) SMPL frame -> s_v (N, V, 256).
Tensor dparf(const TokenFieldsImpl& human, const DPaRFConfig& cfg, const Tokens& t,
             const Tensor& xs) {
  const int64_t N = xs.size(0), V = t.T.size(0), nk = cfg.nk;
  const auto k = std::get<1>(
      (xs.unsqueeze(1) - t.Oc.unsqueeze(0)).pow(2).sum(2).topk(nk, 1, false, true));  // (N, Nk)
  const auto diff =
      xs.unsqueeze(1) - t.Oc.index_select(0, k.flatten()).view({N, nk, 3});       // xs - Oc(k)
  const auto w = torch::softmax(-diff.norm(2, -1) / cfg.softmax_temperature, 1);  // (N, Nk)
  const bool fused = cfg.pe_rounding == PeRounding::fused;
  Tensor g;  // (N, Nk, 63); none: no g_k
  if (cfg.coordinate == Coordinate::relative) {
    // l_k = Rc(k)^T (xs - Oc(k)) = sum_j (xs - Oc(k))_j Rc(k)[j, :], summed in this order as the
    // one-pass query (dparf.cpp) sums it: g_k's high frequencies turn an ulp of l_k into 1e-4.
    const auto Rc = t.Rc.index_select(0, k.flatten()).view({N, nk, 3, 3});
    const auto l = diff.select(2, 0).unsqueeze(2) * Rc.select(2, 0) +
                   diff.select(2, 1).unsqueeze(2) * Rc.select(2, 1) +
                   diff.select(2, 2).unsqueeze(2) * Rc.select(2, 2);
    g = torch::cat({l, sincos(l.reshape({-1, 3}), cfg.pe_freqs, fused).view({N, nk, -1})}, 2);
  } else if (cfg.coordinate == Coordinate::absolute) {
    g = torch::cat({xs, sincos(xs, cfg.pe_freqs, fused)}, 1).unsqueeze(1).expand({N, nk, -1});
  }
  auto field = t.T.index_select(1, k.flatten())
                   .view({V, N, nk, -1})
                   .permute({1, 0, 2, 3});  // T_v(k): (N, V, Nk, 192)
  if (g.defined()) field = torch::cat({field, g.unsqueeze(1).expand({N, V, nk, g.size(2)})}, 3);
  const auto h = (w.view({N, 1, nk, 1}) * field).sum(2);  // h_v (N, V, 255)
  return torch::relu(linear(human.fc_0, h));
}

// SPC baseline: F_v (V, Nv, 192) embedded, averaged into voxels over the posed body, convolved,
// read at xs trilinearly -> s_v (N, V, 256).
Tensor spc(const SPCTrilinearImpl& net, const SPCConfig& cfg, const Tensor& F_v,
           const Tensor& xs_vertices, const Tensor& xs) {
  const double voxel = cfg.voxel_size;
  const auto v = xs_vertices.detach();
  const auto lo = std::get<0>(v.min(0)) - 2 * voxel;
  const auto hi = std::get<0>(v.max(0)) + 2 * voxel;
  const auto dims = ((hi - lo) / voxel).ceil().to(torch::kLong) + 1;  // (x, y, z)
  const auto d = dims.cpu();
  const int64_t nx = d[0].item<int64_t>(), ny = d[1].item<int64_t>(), nz = d[2].item<int64_t>();
  const auto cell = ((v - lo) / voxel).round().to(torch::kLong);
  const auto voxel_of = (cell.select(1, 2) * ny + cell.select(1, 1)) * nx + cell.select(1, 0);
  const auto embedded = linear(net.embed, F_v);  // (V, Nv, C)
  const int64_t V = embedded.size(0), C = embedded.size(2);
  const auto sums =
      torch::zeros({V, nz * ny * nx, C}, embedded.options()).index_add(1, voxel_of, embedded);
  const auto counts = torch::zeros({nz * ny * nx}, embedded.options())
                          .index_add(0, voxel_of, torch::ones_like(voxel_of, embedded.options()));
  auto grid =
      (sums / counts.clamp_min(1).view({1, -1, 1})).permute({0, 2, 1}).reshape({V, C, nz, ny, nx});
  for (size_t i : {0, 2}) {  // Conv3d, ReLU, Conv3d, ReLU
    const auto& c = *net.conv->ptr<torch::nn::Conv3dImpl>(i);
    grid = torch::relu(F::conv3d(grid, c.weight,
                                 F::Conv3dFuncOptions().bias(c.bias).padding(c.options.padding())));
  }
  // xs in [-1, 1] over the voxel centres; outside the grid reads 0.
  const auto at = ((xs - lo) / ((dims - 1).to(lo.dtype()) * voxel)) * 2 - 1;
  const auto f = F::grid_sample(grid, at.view({1, 1, 1, -1, 3}).expand({V, 1, 1, xs.size(0), 3}),
                                F::GridSampleFuncOptions()
                                    .mode(torch::kBilinear)
                                    .padding_mode(torch::kZeros)
                                    .align_corners(true));
  return torch::relu(linear(net.fc_0, f.view({V, C, -1}).permute({2, 0, 1})));
}

// ---- METHOD 3.4: FDI and heads ------------------------------------------------------------------

// softmax over the key views j of q_v . k_j / sqrt(d): (N, V, d) each -> (N, V, V).
Tensor view_attention(const Tensor& q, const Tensor& k) {
  return torch::softmax(torch::bmm(q, k.transpose(1, 2)) / std::sqrt(double(q.size(2))), 2);
}

}  // namespace

Tensor pixel_feature_map(const EncoderImpl& encoder, const std::vector<Tensor>& levels,
                         const Tensor& images) {
  const auto up = F::InterpolateFuncOptions()
                      .size(std::vector<int64_t>{images.size(2), images.size(3)})
                      .mode(torch::kBilinear)
                      .align_corners(true);
  std::vector<Tensor> p;
  for (const auto& level : levels) p.push_back(F::interpolate(level, up));
  if (encoder.upsample_color)
    p.push_back(conv2d(*encoder.upsample_color, images));  // w/o RGB: none
  return torch::cat(p, 1);
}

Tensor grid_sample_pixels(const Tensor& map, const Tensor& uv) {
  TORCH_CHECK(map.dim() == 4, "map must be (V, C, H, W), got ", map.sizes());
  TORCH_CHECK(uv.dim() == 3 && uv.size(1) == map.size(0) && uv.size(2) == 2, "uv must be (N, ",
              map.size(0), ", 2), got ", uv.sizes());
  const auto H = map.size(2), W = map.size(3);
  const auto scale = torch::tensor({2.0 / (W - 1), 2.0 / (H - 1)}, uv.options());
  const auto grid = (uv * scale - 1).permute({1, 0, 2}).unsqueeze(1);  // (V, 1, N, 2)
  const auto out = F::grid_sample(map, grid,
                                  F::GridSampleFuncOptions()
                                      .mode(torch::kBilinear)
                                      .padding_mode(torch::kBorder)
                                      .align_corners(true));
  return out.squeeze(2).permute({2, 0, 1});  // (N, V, C)
}

Tensor NetworkOutput::raw() const { return torch::cat({rgb, sigma.unsqueeze(1)}, 1); }

NetworkOutput network_forward(const TransHumanImpl& model, const FrameInputs& in, const Tensor& pts,
                              const Tensor& dirs) {
  in.check();
  TORCH_CHECK(pts.dim() == 2 && pts.size(1) == 3, "pts must be (N, 3), got ", pts.sizes());
  TORCH_CHECK(dirs.sizes() == pts.sizes(), "dirs must be (N, 3) like pts, got ", dirs.sizes());
  const auto& cfg = model.config();
  const auto opts = in.ref_images.options();
  const auto K = in.K.to(opts), R = in.R.to(opts), T = in.T.to(opts).reshape({-1, 3, 1});
  const auto Rh = in.Rh.to(opts), Th = in.Th.to(opts).reshape({3});
  const auto xs = torch::mm(pts - Th, Rh);  // SMPL frame (N, 3)
  const auto uv = project(pts, K, R, T);    // (N, V, 2)

  // 3.1: the pixel feature p_v of every reference view.
  const auto p_v = pixel_features(*model.encoder, in.ref_images);  // (V, 384, H, W)

  // 3.1-3.3: the human representation s_v, from the painted body.
  Tensor s;  // (N, V, 256); w/o h: none
  if (cfg.fdi.human) {
    const auto vertices = in.vertices.to(opts);
    const auto xs_vertices = torch::mm(vertices - Th, Rh);
    const auto& red = *model.encoder->reduction_layer;
    const auto holder =
        F::conv2d(p_v, red.weight, F::Conv2dFuncOptions().bias(red.bias));  // (V, 192, H, W)
    const auto uv_vertices = project(vertices, K, R, T);
    // F_v(i) = holder_v(uv_v(i)), zero where vertex i is invisible in view v: (V, Nv, 192).
    const auto visibility = in.visibility.to(holder.device(), holder.scalar_type());
    const auto F_v =
        grid_sample_pixels(holder, uv_vertices).permute({1, 0, 2}) * visibility.unsqueeze(-1);
    if (cfg.representation == Representation::spc_trilinear) {
      s = spc(dynamic_cast<const SPCTrilinearImpl&>(*model.human), cfg.spc, F_v, xs_vertices, xs);
    } else {
      const auto& human = dynamic_cast<const TokenFieldsImpl&>(*model.human);
      s = dparf(human, cfg.dparf, transhe(human, cfg, in, F_v, xs_vertices), xs);
    }
  }

  // 3.4: FDI.
  const auto& fdi = *model.fdi;
  Tensor p, o;  // p_v at the points (N, V, 384); FDI's output o_v (N, V, 256)
  if (cfg.fdi.appearance) {
    p = grid_sample_pixels(p_v, uv);
    const auto a = torch::relu(linear(fdi.alpha_res_0, p));
    const auto k = linear(fdi.key0, a), u = linear(fdi.value0, a);
    if (cfg.fdi.human) {
      const auto q = linear(fdi.key1, s), r = linear(fdi.value1, s);
      o = r + torch::bmm(view_attention(q, k), u);
    } else {  // w/o h: the appearance keys attend to each other
      o = u + torch::bmm(view_attention(k, k), u);
    }
  } else {  // w/o a
    o = linear(fdi.value1, s);
  }
  const auto e = torch::relu(linear(fdi.fc_2, torch::relu(linear(fdi.fc_1, o))));

  // 3.4: the heads.
  const auto& heads = *model.heads;
  NetworkOutput out;
  out.sigma = linear(heads.alpha_fc, torch::relu(linear(heads.fc_3, e.mean(1)))).squeeze(1);
  const auto gamma = gamma_of(dirs / dirs.norm(2, 1, true));
  auto c = linear(heads.feature_fc, e);
  if (cfg.fdi.appearance) c = c + linear(heads.rgb_res_0, p);
  const auto gamma_v = gamma.unsqueeze(1).expand({-1, e.size(1), -1});  // (N, V, 27)
  c = torch::relu(linear(heads.view_fc, torch::cat({c, gamma_v}, 2)));
  if (cfg.fdi.appearance) c = c + linear(heads.rgb_res_1, p);
  out.rgb = linear(heads.rgb_fc, torch::relu(linear(heads.fc_4, c.mean(1))));
  return out;
}

}  // namespace th::model
