#include "train/loss.hpp"

#include <torch/torch.h>

#include "core/error.hpp"
#include "metrics/lpips.hpp"

namespace th::train {

torch::Tensor patch_canvas(const torch::Tensor& rgb, const torch::Tensor& patch_index,
                           int64_t patches, int64_t size) {
  auto canvas = torch::zeros({patches * size * size, 3}, rgb.options());
  canvas.index_put_({patch_index.to(rgb.device())}, rgb);
  return canvas.reshape({patches, size, size, 3}).permute({0, 3, 1, 2});
}

PatchLoss patch_loss(const torch::Tensor& rgb, const torch::Tensor& patch_index,
                     const torch::Tensor& target, metrics::LpipsImpl* lpips, double lpips_weight) {
  TORCH_CHECK(target.dim() == 4 && target.size(1) == 3 && target.size(2) == target.size(3),
              "patch_loss: target must be (P, 3, S, S), got ", target.sizes());
  TORCH_CHECK(rgb.dim() == 2 && rgb.size(1) == 3 && patch_index.numel() == rgb.size(0),
              "patch_loss: rgb (R, 3) with one patch index per ray, got ", rgb.sizes(), " and ",
              patch_index.sizes());
  const auto canvas = patch_canvas(rgb, patch_index, target.size(0), target.size(2));
  const auto goal = target.to(rgb.device());
  PatchLoss out;
  out.mse = torch::mse_loss(canvas, goal);
  out.total = out.mse;
  if (lpips) {
    out.perceptual = lpips->forward(canvas * 2 - 1, goal * 2 - 1).mean();
    out.total = out.total + lpips_weight * out.perceptual;
  }
  return out;
}

}  // namespace th::train
