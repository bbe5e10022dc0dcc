#pragma once
// The training loss (METHOD 5): the rendered rays are put back into their patches (black where no
// ray was rendered, as the target's background), then MSE + lpips_weight * LPIPS on the patches.

#include <torch/types.h>

namespace th::metrics {
class LpipsImpl;
}

namespace th::train {

struct PatchLoss {
  torch::Tensor total;       // the scalar that is back-propagated
  torch::Tensor mse;         // scalar
  torch::Tensor perceptual;  // scalar LPIPS; undefined without an LPIPS network
};

// rgb: (R, 3) rendered colours of the sample's rays; patch_index: (R) the slot of each ray in
// the P patches of S x S pixels (flattened, patch-major); target: (P, 3, S, S) in [0, 1].
// `lpips` null: MSE only.
PatchLoss patch_loss(const torch::Tensor& rgb, const torch::Tensor& patch_index,
                     const torch::Tensor& target, metrics::LpipsImpl* lpips, double lpips_weight);

// The patches (P, 3, S, S) that `rgb` fills, the rest black (what patch_loss compares).
torch::Tensor patch_canvas(const torch::Tensor& rgb, const torch::Tensor& patch_index,
                           int64_t patches, int64_t size);

}  // namespace th::train
