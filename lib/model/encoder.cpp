#include "model/encoder.hpp"

#include <ATen/Parallel.h>

#include <algorithm>

#include "core/error.hpp"
#include "io/npy.hpp"
#include "model/kernels/work.hpp"

namespace th::model {
namespace {

namespace F = torch::nn::functional;

torch::nn::Conv2d conv(int64_t in, int64_t out, int64_t k, int64_t stride, int64_t pad, bool bias) {
  return torch::nn::Conv2d(
      torch::nn::Conv2dOptions(in, out, k).stride(stride).padding(pad).bias(bias));
}

// torchvision's ResNet init: kaiming_normal(fan_out, relu) for convolutions.
void init_conv(torch::nn::Conv2d& c) {
  torch::NoGradGuard no_grad;
  torch::nn::init::kaiming_normal_(c->weight, 0.0, torch::kFanOut, torch::kReLU);
}

// Channel ranges of the levels inside p_v: [0, 64), [64, 128), [128, 256); colour [256, 384).
constexpr int64_t kLevelBegin[] = {0, 64, 128, 256};

}  // namespace

// ---- BatchNorm -----------------------------------------------------------------------------

BatchNormImpl::BatchNormImpl(int64_t channels, bool batch_stats)
    : batch_stats_at_inference(batch_stats) {
  weight = register_parameter("weight", torch::ones({channels}));
  bias = register_parameter("bias", torch::zeros({channels}));
  running_mean = register_buffer("running_mean", torch::zeros({channels}));
  running_var = register_buffer("running_var", torch::ones({channels}));
  num_batches_tracked = register_buffer("num_batches_tracked", torch::zeros({}, torch::kLong));
}

namespace {

// Per-channel sums over (N, H, W) of a (N, C, H, W) tensor, in float64.
torch::Tensor channel_sums(const torch::Tensor& t) {
  return t.sum({0, 2, 3}, false, torch::kFloat64);
}

// The ranks' reducer as autograd's saved data holds it (a capsule): the graph keeps it alive
// until backward runs, even if the module's is replaced in between.
struct ReducerHolder : torch::CustomClassHolder {
  explicit ReducerHolder(std::shared_ptr<const StatsReducer> r) : reduce(std::move(r)) {}
  std::shared_ptr<const StatsReducer> reduce;
};

// Batch normalisation over the images of every rank (see BatchNormImpl). Statistics and their
// sums are float64, the output has x's type.
struct SyncBatchNorm : torch::autograd::Function<SyncBatchNorm> {
  static torch::Tensor forward(torch::autograd::AutogradContext* ctx, const torch::Tensor& x,
                               const torch::Tensor& weight, const torch::Tensor& bias,
                               torch::Tensor running_mean, torch::Tensor running_var,
                               c10::intrusive_ptr<ReducerHolder> holder, double momentum,
                               double eps) {
    const StatsReducer& reduce = *holder->reduce;
    TORCH_CHECK(x.dim() == 4, "synchronised BatchNorm expects (N, C, H, W), got ", x.sizes());
    const int64_t C = x.size(1);
    const auto xd = x.to(torch::kFloat64);
    auto stats = torch::cat({channel_sums(xd), channel_sums(xd * xd),
                             torch::full({1}, double(x.numel() / C), torch::kFloat64)});
    reduce(stats);
    const double count = stats[2 * C].item<double>();
    TORCH_CHECK(count > 1, "synchronised BatchNorm over ", count, " values per channel");
    const auto mean = stats.slice(0, 0, C) / count;
    const auto var = (stats.slice(0, C, 2 * C) / count - mean * mean).clamp_min(0);
    const auto invstd = (var + eps).rsqrt();
    {
      torch::NoGradGuard no_grad;
      running_mean.mul_(1 - momentum).add_(mean.to(running_mean.scalar_type()), momentum);
      running_var.mul_(1 - momentum)
          .add_((var * (count / (count - 1))).to(running_var.scalar_type()), momentum);
    }
    const auto m4 = mean.view({1, C, 1, 1}), s4 = invstd.view({1, C, 1, 1});
    const auto xhat = (xd - m4) * s4;
    ctx->save_for_backward({x, weight, mean, invstd});
    ctx->saved_data["count"] = count;
    ctx->saved_data["reduce"] = c10::IValue::make_capsule(holder);
    return (xhat * weight.to(torch::kFloat64).view({1, C, 1, 1}) +
            bias.to(torch::kFloat64).view({1, C, 1, 1}))
        .to(x.scalar_type());
  }

  static torch::autograd::variable_list backward(torch::autograd::AutogradContext* ctx,
                                                 torch::autograd::variable_list grad) {
    const auto saved = ctx->get_saved_variables();
    const auto &x = saved[0], &weight = saved[1], &mean = saved[2], &invstd = saved[3];
    const auto holder =
        c10::static_intrusive_pointer_cast<ReducerHolder>(ctx->saved_data["reduce"].toCapsule());
    const StatsReducer& reduce = *holder->reduce;
    const double count = ctx->saved_data["count"].toDouble();
    const int64_t C = x.size(1);
    const auto dy = grad[0].to(torch::kFloat64);
    const auto s4 = invstd.view({1, C, 1, 1});
    const auto xhat = (x.to(torch::kFloat64) - mean.view({1, C, 1, 1})) * s4;
    const auto sum_dy = channel_sums(dy), sum_dy_xhat = channel_sums(dy * xhat);
    auto both = torch::cat({sum_dy, sum_dy_xhat});
    reduce(both);
    const auto mean_dy = (both.slice(0, 0, C) / count).view({1, C, 1, 1});
    const auto mean_dy_xhat = (both.slice(0, C, 2 * C) / count).view({1, C, 1, 1});
    const auto dx =
        (weight.to(torch::kFloat64).view({1, C, 1, 1}) * s4) * (dy - mean_dy - xhat * mean_dy_xhat);
    return {dx.to(x.scalar_type()),
            sum_dy_xhat.to(weight.scalar_type()),
            sum_dy.to(weight.scalar_type()),
            torch::Tensor(),
            torch::Tensor(),
            torch::Tensor(),
            torch::Tensor(),
            torch::Tensor()};
  }
};

}  // namespace

int synchronise_batchnorm(torch::nn::Module& module, std::shared_ptr<const StatsReducer> reduce) {
  int n = 0;
  for (const auto& m : module.modules(/*include_self=*/true))
    if (auto* bn = dynamic_cast<BatchNormImpl*>(m.get())) {
      bn->sync = reduce;
      ++n;
    }
  return n;
}

torch::Tensor BatchNormImpl::forward(const torch::Tensor& x) {
  constexpr double momentum = 0.1, eps = 1e-5;
  if (is_training()) {
    {
      torch::NoGradGuard no_grad;
      num_batches_tracked += 1;
    }
    if (sync)
      return SyncBatchNorm::apply(x, weight, bias, running_mean, running_var,
                                  c10::make_intrusive<ReducerHolder>(sync), momentum, eps);
    return torch::batch_norm(x, weight, bias, running_mean, running_var, true, momentum, eps,
                             false);
  }
  if (batch_stats_at_inference)  // [parity] statistics of the reference views, not updated
    return torch::batch_norm(x, weight, bias, {}, {}, true, momentum, eps, false);
  return torch::batch_norm(x, weight, bias, running_mean, running_var, false, momentum, eps, false);
}

// ---- ResNet-18 trunk -------------------------------------------------------------------------

BasicBlockImpl::BasicBlockImpl(int64_t in, int64_t out, int64_t stride, bool batch_stats) {
  conv1 = register_module("conv1", conv(in, out, 3, stride, 1, false));
  bn1 = register_module("bn1", BatchNorm(out, batch_stats));
  conv2 = register_module("conv2", conv(out, out, 3, 1, 1, false));
  bn2 = register_module("bn2", BatchNorm(out, batch_stats));
  init_conv(conv1);
  init_conv(conv2);
  if (stride != 1 || in != out) {
    auto down = conv(in, out, 1, stride, 0, false);
    init_conv(down);
    downsample =
        register_module("downsample", torch::nn::Sequential(down, BatchNorm(out, batch_stats)));
  }
}

torch::Tensor BasicBlockImpl::forward(const torch::Tensor& x) {
  auto y = torch::relu(bn1(conv1(x)));
  y = bn2(conv2(y));
  return torch::relu(y + (downsample ? downsample->forward(x) : x));
}

ResNetTrunkImpl::ResNetTrunkImpl(bool batch_stats) {
  conv1 = register_module("conv1", conv(3, 64, 7, 2, 3, false));
  init_conv(conv1);
  bn1 = register_module("bn1", BatchNorm(64, batch_stats));
  layer1 = register_module("layer1", torch::nn::Sequential(BasicBlock(64, 64, 1, batch_stats),
                                                           BasicBlock(64, 64, 1, batch_stats)));
  layer2 = register_module("layer2", torch::nn::Sequential(BasicBlock(64, 128, 2, batch_stats),
                                                           BasicBlock(128, 128, 1, batch_stats)));
}

std::vector<torch::Tensor> ResNetTrunkImpl::forward(const torch::Tensor& x) {
  auto l0 = torch::relu(bn1(conv1(x)));
  auto l1 = layer1->forward(F::max_pool2d(l0, F::MaxPool2dFuncOptions(3).stride(2).padding(1)));
  auto l2 = layer2->forward(l1);
  return {l0, l1, l2};
}

torch::Tensor to_table(const torch::Tensor& map) {
  TORCH_CHECK(map.dim() == 4, "feature map must be (V, C, h, w), got ", map.sizes());
  return map.permute({0, 2, 3, 1}).reshape({-1, map.size(1)});
}

// ---- geometry of sampling --------------------------------------------------------------------

Taps PixelGeometry::stacked_level_taps(const torch::Tensor& uv, const torch::Tensor& view) const {
  std::vector<int64_t> offsets;
  int64_t offset = 0;
  for (const auto& [h, w] : level_sizes) {
    offsets.push_back(offset);
    offset += views * h * w;
  }
  return kernels::level_taps(uv, view, {level_sizes, offsets, height, width});
}

Taps PixelGeometry::image_taps(const torch::Tensor& uv, const torch::Tensor& view) const {
  return kernels::level_taps(uv, view, {{{height, width}}, {0}, height, width});
}

std::pair<torch::Tensor, torch::Tensor> PixelGeometry::point_view_rows(const torch::Tensor& uv) {
  const auto n = uv.size(0), V = uv.size(1);
  const auto options = torch::TensorOptions().dtype(torch::kLong).device(uv.device());
  auto view = torch::arange(V, options).repeat({n});
  render::count_work(0, kernels::bytes_of(view));
  return {uv.reshape({-1, 2}), view};
}

torch::Tensor PixelReadout::sample(const Taps& level_taps, const Taps& image_taps) const {
  auto out = kernels::weighted_gather(table, level_taps, table_grad_sink);
  if (image_weight.defined())
    out.addmm_(kernels::weighted_gather(image_table, image_taps), image_weight.t());
  return out.add_(bias);
}

void PixelReadout::visit(const TensorVisitor& fn) {
  fn(table, &table_grad_sink);
  fn(image_table, nullptr);
  fn(image_weight, nullptr);
  fn(bias, nullptr);
}

// ---- encoder ---------------------------------------------------------------------------------

EncoderImpl::EncoderImpl(const EncoderConfig& config, bool raw_rgb, int64_t holder_channels) {
  model = register_module("model", ResNetTrunk(config.batchnorm == BatchNormStats::batch));
  // Registered (and initialised) in this order: the random initial weights depend on it.
  reduction_layer =
      register_module("reduction_layer", conv(raw_rgb ? 384 : 256, holder_channels, 1, 1, 0, true));
  if (raw_rgb) upsample_color = register_module("upsample_color", conv(3, 128, 1, 1, 0, true));
}

EncodedViews EncoderImpl::forward(const torch::Tensor& images) {
  TORCH_CHECK(images.dim() == 4 && images.size(1) == 3, "encoder images must be (V, 3, H, W), got ",
              images.sizes());
  EncodedViews enc;
  enc.images = images;
  enc.levels = model->forward(images);
  enc.geometry.views = images.size(0);
  enc.geometry.height = images.size(2);
  enc.geometry.width = images.size(3);
  for (const auto& l : enc.levels) enc.geometry.level_sizes.emplace_back(l.size(2), l.size(3));
  return enc;
}

torch::Tensor EncoderImpl::sample_pixel_features(const EncodedViews& enc, const Taps& level_taps,
                                                 const Taps& image_taps) const {
  // level_taps: stacked taps (9 per level, 4 for a level of the image's size); split them back.
  std::vector<torch::Tensor> parts;
  int64_t offset = 0, col = 0;
  const auto& g = enc.geometry;
  for (const auto& l : enc.levels) {
    const int64_t taps_per_level = (l.size(2) == g.height && l.size(3) == g.width) ? 4 : 9;
    Taps t{level_taps.index.narrow(1, col, taps_per_level) - offset,
           level_taps.weight.narrow(1, col, taps_per_level)};
    parts.push_back(kernels::weighted_gather(to_table(l), t));
    offset += l.size(0) * l.size(2) * l.size(3);
    col += taps_per_level;
  }
  if (upsample_color) {
    const auto rgb = kernels::weighted_gather(to_table(enc.images), image_taps);
    parts.push_back(F::linear(rgb, upsample_color->weight.flatten(1), upsample_color->bias));
  }
  return torch::cat(parts, 1);
}

std::pair<torch::Tensor, torch::Tensor> PixelWindows::pixels(
    const torch::TensorOptions& options) const {
  std::vector<torch::Tensor> uv, view;
  for (size_t v = 0; v < offset.size(); ++v) {
    const auto ys = torch::arange(y0[v], y0[v] + h[v], options);
    const auto xs = torch::arange(x0[v], x0[v] + w[v], options);
    const auto grid = torch::meshgrid({ys, xs}, "ij");
    uv.push_back(torch::stack({grid[1].flatten(), grid[0].flatten()}, 1));
    view.push_back(torch::full({h[v] * w[v]}, int64_t(v), options.dtype(torch::kLong)));
  }
  return {torch::cat(uv), torch::cat(view)};
}

LevelFootprint PixelWindows::footprint(const PixelGeometry& g,
                                       const torch::TensorOptions& options) const {
  LevelFootprint f(g.level_sizes.size(), std::vector<TexelRect>(offset.size()));
  std::vector<float> corners;
  std::vector<int64_t> views;
  for (size_t v = 0; v < offset.size(); ++v) {
    if (w[v] <= 0 || h[v] <= 0) continue;
    corners.insert(corners.end(),
                   {float(x0[v]), float(y0[v]), float(x0[v] + w[v] - 1), float(y0[v] + h[v] - 1)});
    views.insert(views.end(), {int64_t(v), int64_t(v)});
  }
  if (views.empty()) return f;
  const int64_t n = int64_t(views.size());
  const auto uv = torch::from_blob(corners.data(), {n, 2}, torch::kFloat).to(options);
  const auto view = torch::from_blob(views.data(), {n}, torch::kLong).clone();
  const auto taps = g.stacked_level_taps(uv, view);
  const auto index = taps.index.contiguous();
  const int64_t T_ = index.size(1);
  const int64_t* idx = index.data_ptr<int64_t>();
  std::vector<int64_t> level_offset;
  int64_t rows = 0;
  for (const auto& [lh, lw] : g.level_sizes) {
    level_offset.push_back(rows);
    rows += g.views * lh * lw;
  }
  for (int64_t m = 0; m < n; ++m)
    for (int64_t k = 0; k < T_; ++k) {
      const int64_t i = idx[m * T_ + k];
      size_t l = level_offset.size() - 1;
      while (l > 0 && i < level_offset[l]) --l;
      const auto [lh, lw] = g.level_sizes[l];
      const int64_t r = i - level_offset[l] - views[m] * lh * lw, y = r / lw, x = r % lw;
      auto& t = f[l][views[m]];
      const bool first = t.x1 <= t.x0;
      t.x0 = first ? x : std::min(t.x0, x);
      t.y0 = first ? y : std::min(t.y0, y);
      t.x1 = first ? x + 1 : std::max(t.x1, x + 1);
      t.y1 = first ? y + 1 : std::max(t.y1, y + 1);
    }
  return f;
}

std::pair<Taps, torch::Tensor> PixelWindows::taps(const torch::Tensor& uv,
                                                  const torch::Tensor& view, int64_t H,
                                                  int64_t W) const {
  TORCH_CHECK(uv.device().is_cpu(), "window taps: uv must be on CPU");
  // grid_sample's 2 x 2 taps into the (V H W) rows of the whole images, then moved to the rows
  // of the windows; a point with a tap outside its view's window gets row 0 and weight 0.
  Taps t = kernels::level_taps(uv, view, {{{H, W}}, {0}, H, W});
  const int64_t M = t.index.size(0), T_ = t.index.size(1), views = int64_t(offset.size());
  auto inside = torch::empty({M}, t.index.options().dtype(torch::kBool));
  render::count_work(8.0 * double(M * T_), 2 * kernels::bytes_of(t.index) + double(M));
  int64_t* ti = t.index.data_ptr<int64_t>();
  bool* in = inside.data_ptr<bool>();
  AT_DISPATCH_FLOATING_TYPES(t.weight.scalar_type(), "window_taps", [&] {
    scalar_t* tw = t.weight.data_ptr<scalar_t>();
    at::parallel_for(0, M, 4096, [&](int64_t b, int64_t e) {
      for (int64_t m = b; m < e; ++m) {
        int64_t* i = ti + T_ * m;
        bool ok = true;
        for (int64_t k = 0; k < T_ && ok; ++k) {
          const int64_t v = i[k] / (H * W), y = i[k] % (H * W) / W, x = i[k] % W;
          ok = v >= 0 && v < views && x >= x0[v] && x < x0[v] + w[v] && y >= y0[v] &&
               y < y0[v] + h[v];
          if (ok) i[k] = offset[v] + (y - y0[v]) * w[v] + (x - x0[v]);
        }
        in[m] = ok;
        if (!ok)
          for (int64_t k = 0; k < T_; ++k) i[k] = 0, tw[T_ * m + k] = 0;
      }
    });
  });
  return {t, inside};
}

PixelReadout EncoderImpl::make_readout(const EncodedViews& enc, const torch::Tensor& weight,
                                       const torch::Tensor& bias,
                                       const LevelFootprint* footprint) const {
  TORCH_CHECK(weight.dim() == 2 && weight.size(1) == pixel_channels(),
              "readout weight must be (Cout, ", pixel_channels(), "), got ", weight.sizes());
  TORCH_CHECK(!footprint || footprint->size() == enc.levels.size(),
              "readout footprint: one entry per level expected");
  PixelReadout r;
  if (footprint) {  // each level's rectangles into their rows of one stacked table
    int64_t rows = 0;
    for (const auto& level : enc.levels) rows += level.size(0) * level.size(2) * level.size(3);
    r.table = torch::empty({rows, weight.size(0)}, enc.levels[0].options());
    int64_t offset = 0;
    for (size_t l = 0; l < enc.levels.size(); ++l) {
      const auto& level = enc.levels[l];
      const int64_t V = level.size(0), h = level.size(2), w = level.size(3);
      const auto wt = weight.slice(1, kLevelBegin[l], kLevelBegin[l + 1]).t();
      const auto maps = r.table.narrow(0, offset, V * h * w).view({V, h, w, -1});
      for (int64_t v = 0; v < V && v < int64_t((*footprint)[l].size()); ++v) {
        const auto& t = (*footprint)[l][v];
        if (t.x1 <= t.x0 || t.y1 <= t.y0) continue;
        const auto texels = level[v].slice(1, t.y0, t.y1).slice(2, t.x0, t.x1);  // (C, hh, ww)
        maps[v]
            .slice(0, t.y0, t.y1)
            .slice(1, t.x0, t.x1)
            .copy_(torch::mm(texels.permute({1, 2, 0}).reshape({-1, level.size(1)}), wt)
                       .view({t.y1 - t.y0, t.x1 - t.x0, -1}));
      }
      offset += V * h * w;
    }
  } else {
    std::vector<torch::Tensor> tables;
    for (size_t l = 0; l < enc.levels.size(); ++l) {
      const auto w = weight.slice(1, kLevelBegin[l], kLevelBegin[l + 1]);
      tables.push_back(torch::mm(to_table(enc.levels[l]), w.t()));
    }
    r.table = torch::cat(tables, 0);
  }
  r.image_table = to_table(enc.images).detach();
  r.bias = bias;
  if (upsample_color) {
    const auto wc = weight.slice(1, 256, 384);  // (Cout, 128)
    r.image_weight = torch::mm(wc, upsample_color->weight.flatten(1));
    r.bias = bias + torch::mv(wc, upsample_color->bias);
  }
  return r;
}

torch::Tensor EncoderImpl::paint(const EncodedViews& enc, const torch::Tensor& uv,
                                 const torch::Tensor& visibility) const {
  const auto V = uv.size(0), nv = uv.size(1);
  TORCH_CHECK(uv.dim() == 3 && uv.size(2) == 2, "paint uv must be (V, Nv, 2), got ", uv.sizes());
  TORCH_CHECK(visibility.sizes() == torch::IntArrayRef({V, nv}), "visibility must be (", V, ", ",
              nv, "), got ", visibility.sizes());
  const auto flat = uv.reshape({-1, 2});
  const auto view = torch::arange(V, uv.options().dtype(torch::kLong)).repeat_interleave(nv);
  const auto p = sample_pixel_features(enc, enc.geometry.stacked_level_taps(flat, view),
                                       enc.geometry.image_taps(flat, view));
  const auto holder = F::linear(p, reduction_layer->weight.flatten(1), reduction_layer->bias);
  return holder.view({V, nv, -1}) *
         visibility.unsqueeze(-1).to(holder.device(), holder.scalar_type());
}

void load_pretrained_encoder(EncoderImpl& encoder, const std::filesystem::path& npz) {
  const auto state = io::read_npz(npz);
  const auto source = npz.string();
  auto& model = encoder.model;
  torch::NoGradGuard no_grad;
  auto assign = [&](const std::string& name, torch::Tensor& dst) {
    const auto it = state.find(name);
    if (it == state.end()) fail(source, ": missing key '", name, "'");
    if (it->second.sizes() != dst.sizes())
      fail(source, ": key '", name, "' has shape ", it->second.sizes(), ", expected ", dst.sizes());
    dst.copy_(it->second);
  };
  for (auto& p : model->named_parameters()) assign(p.key(), p.value());
  for (auto& b : model->named_buffers()) {
    if (b.key().find("num_batches_tracked") != std::string::npos && !state.count(b.key())) continue;
    assign(b.key(), b.value());
  }
}

}  // namespace th::model
