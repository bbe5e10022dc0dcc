#pragma once
// METHOD 3.1: the image encoder (ResNet-18 up to layer2, torchvision layout and names), the
// 384-channel pixel feature p_v, the reduction to model.transhe.dim (192) channels and the
// painting of the body.
//
// The pixel feature is the concatenation of three bilinearly upsampled ResNet levels and a 1x1
// convolution of the raw image. It is never materialised at full resolution: sampling reads
// each level at the taps of its upsampled map (kernels::level_taps, exact), and per-pixel linear
// layers that follow p_v are applied to each level before sampling (METHOD 9), see PixelReadout.

#include <torch/torch.h>

#include <filesystem>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "core/config.hpp"
#include "model/kernels/gather.hpp"

namespace th::model {

// What a stage of the per-frame state shows of its tensors: fn(tensor, its gradient-sink slot,
// or null when it has none).
using TensorVisitor = std::function<void(torch::Tensor& tensor, torch::Tensor* grad_sink)>;

// (V, C, h, w) map -> (V * h * w, C) channels-last table for weighted_gather.
torch::Tensor to_table(const torch::Tensor& map);

// Sums a float64 tensor in place over the data-parallel ranks: what synchronised BatchNorm
// needs of the ranks (train/ supplies it from the communicator; the model knows no ranks).
using StatsReducer = std::function<void(torch::Tensor&)>;

// BatchNorm2d with torchvision's parameter names. At inference it normalises with the
// statistics of the current batch (the V reference images) when `batch_stats_at_inference`
// [parity, METHOD 3.1], otherwise with the running statistics.
//
// In training with `sync` set (several ranks, `train.sync_batchnorm`), the batch is every
// rank's images together, as the reference trained with SyncBatchNorm: per-channel sums of x
// and x^2 (float64) are summed over the ranks in the forward pass, and those of dy and
// dy * x_hat in the backward pass, so each rank's input gradient is that of one batch of all
// ranks' images. The weight and bias gradients stay per rank (the gradient all-reduce sums them).
class BatchNormImpl : public torch::nn::Module {
 public:
  BatchNormImpl(int64_t channels, bool batch_stats_at_inference);
  torch::Tensor forward(const torch::Tensor& x);

  torch::Tensor weight, bias, running_mean, running_var, num_batches_tracked;
  bool batch_stats_at_inference;
  std::shared_ptr<const StatsReducer> sync;  // null: this rank's batch alone
};
TORCH_MODULE(BatchNorm);

// Sets (or, with nullptr, clears) the reducer of every BatchNorm inside `module`; returns how
// many there are.
int synchronise_batchnorm(torch::nn::Module& module, std::shared_ptr<const StatsReducer> reduce);

class BasicBlockImpl : public torch::nn::Module {
 public:
  BasicBlockImpl(int64_t in, int64_t out, int64_t stride, bool batch_stats);
  torch::Tensor forward(const torch::Tensor& x);

  torch::nn::Conv2d conv1{nullptr}, conv2{nullptr};
  BatchNorm bn1{nullptr}, bn2{nullptr};
  torch::nn::Sequential downsample{nullptr};
};
TORCH_MODULE(BasicBlock);

// conv1, bn1, relu, maxpool, layer1, layer2 of torchvision's resnet18.
class ResNetTrunkImpl : public torch::nn::Module {
 public:
  explicit ResNetTrunkImpl(bool batch_stats);
  // x: (V, 3, H, W) -> {L0 (V, 64, H/2, W/2), L1 (V, 64, H/4, W/4), L2 (V, 128, H/8, W/8)}
  std::vector<torch::Tensor> forward(const torch::Tensor& x);

  torch::nn::Conv2d conv1{nullptr};
  BatchNorm bn1{nullptr};
  torch::nn::Sequential layer1{nullptr}, layer2{nullptr};
};
TORCH_MODULE(ResNetTrunk);

// Where the levels of one frame's views live and how to sample them (plain geometry).
struct PixelGeometry {
  int64_t views = 0, height = 0, width = 0;
  std::vector<std::pair<int64_t, int64_t>> level_sizes;  // (h, w) per ResNet level

  // Taps for points uv: (M, 2) pixel coordinates, view: (M) int64, into
  // - all levels stacked in one table (level 0 of all views, then level 1, ...),
  // - the image table (V H W rows; plain bilinear).
  Taps stacked_level_taps(const torch::Tensor& uv, const torch::Tensor& view) const;
  Taps image_taps(const torch::Tensor& uv, const torch::Tensor& view) const;
  // The rows of N points x V views, point-major: uv (N, V, 2) as (N V, 2), and each row's view
  // (N V) int64; the arguments of the taps above.
  static std::pair<torch::Tensor, torch::Tensor> point_view_rows(const torch::Tensor& uv);
};

// The encoder output of one frame.
struct EncodedViews {
  std::vector<torch::Tensor> levels;  // L0, L1, L2 (V, C_l, h_l, w_l)
  torch::Tensor images;               // (V, 3, H, W)
  PixelGeometry geometry;
};

// A per-pixel linear layer y = W p_v + b on the pixel feature, precomputed per frame on each
// level (METHOD 9: a linear layer commutes with bilinear upsampling and sampling). Sampled with
// PixelReadout::sample it equals linear(grid_sample(pixel_features)) up to float rounding.
struct PixelReadout {
  torch::Tensor table;        // (sum_l V h_l w_l, Cout) level maps, channels-last, stacked
  torch::Tensor image_table;  // (V H W, 3) the raw images, channels-last (no gradient)
  torch::Tensor
      image_weight;    // (Cout, 3) composed weight of the raw-RGB channels; undefined w/o RGB
  torch::Tensor bias;  // (Cout)
  torch::Tensor table_grad_sink;  // optional, see weighted_gather

  // level_taps/image_taps from PixelGeometry for M points; returns (M, Cout).
  torch::Tensor sample(const Taps& level_taps, const Taps& image_taps) const;
  void visit(const TensorVisitor& fn);
};

// One rectangle of pixels per view, [x0, x0 + w) x [y0, y0 + h), whose pixels are stacked view
// after view (row-major within a view) in a table of full-resolution values.
// A rectangle of texels of one view's level map: [x0, x1) x [y0, y1).
struct TexelRect {
  int64_t x0 = 0, y0 = 0, x1 = 0, y1 = 0;
};
// Per level, per view: the texels a readout table needs (PixelWindows::footprint).
using LevelFootprint = std::vector<std::vector<TexelRect>>;

struct PixelWindows {
  std::vector<int64_t> x0, y0, w, h, offset;  // per view; offset: the view's first row
  int64_t rows() const { return offset.empty() ? 0 : offset.back() + w.back() * h.back(); }
  bool empty() const { return offset.empty(); }

  // The rows of every window pixel (rows(), 2) pixel coordinates (x, y) and their views (rows()).
  std::pair<torch::Tensor, torch::Tensor> pixels(const torch::TensorOptions& options) const;
  // Bilinear taps (grid_sample: border padding, align_corners) of M points into the stacked
  // table, uv: (M, 2) pixel coordinates of an (H, W) image, view: (M). Returns the taps (M, 4)
  // and whether each point's four texels all lie in its view's window, (M) bool; the taps of a
  // point outside read row 0 with weight 0.
  std::pair<Taps, torch::Tensor> taps(const torch::Tensor& uv, const torch::Tensor& view, int64_t H,
                                      int64_t W) const;
  // The texels of each level map that the windows' pixels read through the level taps
  // (PixelGeometry::stacked_level_taps): per level and view, the smallest rectangle holding
  // the taps of the window's corner pixels (the taps move monotonically with the pixel).
  LevelFootprint footprint(const PixelGeometry& g, const torch::TensorOptions& options) const;
};

// A readout in window form (inference, model/pixels.hpp): y at every pixel of the windows,
// stacked as PixelWindows orders them, and the layer itself for points outside the windows.
struct WindowReadout {
  torch::Tensor table;               // (rows, Cout)
  torch::Tensor weight, layer_bias;  // (Cout, Cpix), (Cout): the layer's own parameters
  void visit(const TensorVisitor& fn) { fn(table, nullptr); }
};

class EncoderImpl : public torch::nn::Module {
 public:
  // raw_rgb: include the 128 upsample_color channels in p_v (false: the "w/o RGB" ablation);
  // holder_channels: the width of the painted features (the reduction layer's output), which
  // is model.transhe.dim.
  EncoderImpl(const EncoderConfig& config, bool raw_rgb, int64_t holder_channels);

  // images: (V, 3, H, W) in [0, 1] (no mean/std normalisation [parity]).
  EncodedViews forward(const torch::Tensor& images);

  int64_t pixel_channels() const { return upsample_color ? 384 : 256; }

  // p_v at M points without materialising it; returns (M, 384).
  torch::Tensor sample_pixel_features(const EncodedViews& enc, const Taps& level_taps,
                                      const Taps& image_taps) const;
  // Per-level precomputation of y = W p + b. weight: (Cout, 384), bias: (Cout).
  // footprint (optional): only the table rows of those texels are computed, the others left
  // unwritten (inference: the window form reads no other row, and untouched pages are never
  // allocated).
  PixelReadout make_readout(const EncodedViews& enc, const torch::Tensor& weight,
                            const torch::Tensor& bias,
                            const LevelFootprint* footprint = nullptr) const;

  // METHOD 3.1 painting: holder features at the projections of the body vertices, zero where
  // the vertex is invisible. uv: (V, Nv, 2), visibility: (V, Nv) -> (V, Nv, holder channels).
  torch::Tensor paint(const EncodedViews& enc, const torch::Tensor& uv,
                      const torch::Tensor& visibility) const;

  ResNetTrunk model{nullptr};
  torch::nn::Conv2d reduction_layer{nullptr},
      upsample_color{nullptr};  // upsample_color: null w/o RGB
};
TORCH_MODULE(Encoder);

// ImageNet ResNet-18 weights for the encoder's trunk (METHOD 3.1): an .npz with torchvision's
// resnet18 state dict names (conv1.weight, bn1.running_mean, layer1.0...; layer3, layer4 and fc
// are ignored), written by scripts/export_pretrained.py. Throws th::Error naming a missing or
// mis-shaped key. (Whole models: pipeline/checkpoint.hpp, pipeline/reference_import.hpp.)
void load_pretrained_encoder(EncoderImpl& encoder, const std::filesystem::path& npz);

}  // namespace th::model
