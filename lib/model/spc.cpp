#include "model/spc.hpp"

namespace th::model {

namespace F = torch::nn::functional;

SPCTrilinearImpl::SPCTrilinearImpl(const ModelConfig& config) : config_(config.spc) {
  const int64_t C = config_.channels;
  embed = register_module("embed", torch::nn::Linear(config.transhe.dim, C));
  auto conv3 = [&] { return torch::nn::Conv3d(torch::nn::Conv3dOptions(C, C, 3).padding(1)); };
  conv = register_module(
      "conv", torch::nn::Sequential(conv3(), torch::nn::ReLU(), conv3(), torch::nn::ReLU()));
  fc_0 = register_module("fc_0", torch::nn::Linear(C, 256));
}

HumanStage SPCTrilinearImpl::prepare(const FrameInputs& /*in*/, const PaintedBody& body) {
  const auto& painted = body.features;
  const auto& xs_vertices = body.xs_vertices;
  const double voxel = config_.voxel_size;
  torch::Tensor lo, dims;
  {
    torch::NoGradGuard no_grad;
    // Grid over the posed body with two voxels of margin.
    lo = std::get<0>(xs_vertices.min(0)) - 2 * voxel;
    const auto hi = std::get<0>(xs_vertices.max(0)) + 2 * voxel;
    dims = ((hi - lo) / voxel).ceil().to(torch::kLong) + 1;  // (x, y, z) sizes
  }
  const auto d = dims.cpu();
  const int64_t nx = d[0].item<int64_t>(), ny = d[1].item<int64_t>(), nz = d[2].item<int64_t>();
  const auto cell = ((xs_vertices.detach() - lo) / voxel).round().to(torch::kLong);
  const auto flat = (cell.select(1, 2) * ny + cell.select(1, 1)) * nx + cell.select(1, 0);
  const auto V = painted.size(0);
  const auto feats = embed(painted);  // (V, Nv, C)
  const auto C = feats.size(2);
  auto sums = torch::zeros({V, nz * ny * nx, C}, feats.options()).index_add(1, flat, feats);
  const auto counts = torch::zeros({nz * ny * nx}, feats.options())
                          .index_add(0, flat, torch::ones({flat.size(0)}, feats.options()));
  auto grid =
      (sums / counts.clamp_min(1).view({1, -1, 1})).permute({0, 2, 1}).reshape({V, C, nz, ny, nx});
  return SPCStage{conv->forward(grid), lo, (dims - 1).to(lo.dtype()) * voxel};
}

torch::Tensor SPCTrilinearImpl::forward(const HumanStage& human, const torch::Tensor& xs,
                                        const Products& /*products*/) {
  const auto& stage = std::get<SPCStage>(human);
  const auto& grid = stage.grid;
  const auto V = grid.size(0), n = xs.size(0);
  // (x, y, z) -> [-1, 1] over the voxel centres (align_corners); outside the grid reads 0.
  const auto g = ((xs - stage.lo) / stage.extent) * 2 - 1;
  const auto coords = g.view({1, 1, 1, n, 3}).expand({V, 1, 1, n, 3});
  const auto f = F::grid_sample(grid, coords,
                                F::GridSampleFuncOptions()
                                    .mode(torch::kBilinear)
                                    .padding_mode(torch::kZeros)
                                    .align_corners(true));
  return torch::relu(fc_0(f.view({V, -1, n}).permute({2, 0, 1})));  // (N, V, 256)
}

}  // namespace th::model
