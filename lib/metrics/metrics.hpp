#pragma once
// Image metrics of the evaluation protocol (METHOD 6): PSNR over the valid rays, SSIM as
// scikit-image's structural_similarity with the protocol's settings, and the crop both SSIM
// and LPIPS use.

#include <torch/types.h>

namespace th::metrics {

// PSNR of predicted vs ground-truth colours (N, 3) in [0, 1]: -10 log10(mean squared error)
// over all values (METHOD 6: valid rays only, 3 channels), float64 arithmetic.
double psnr(const torch::Tensor& pred, const torch::Tensor& gt);

// skimage.metrics.structural_similarity(a, b, channel_axis=-1, data_range=2.0) with its float
// defaults: 7x7 uniform window, sample covariance (N/(N-1)), K1 0.01, K2 0.03; the mean of the
// SSIM map cropped by 3 px at each border, averaged over channels. a, b: (H, W, C), float64.
double ssim(const torch::Tensor& a, const torch::Tensor& b, double data_range = 2.0);

// The protocol's crop (METHOD 6): the images (H, W, 3) with everything outside `valid` (H, W)
// bool set to black, cropped to the bounding rectangle of `valid`.
struct Crop {
  torch::Tensor pred, gt;  // (h, w, 3)
};
Crop crop_to_valid(const torch::Tensor& pred, const torch::Tensor& gt, const torch::Tensor& valid);

}  // namespace th::metrics
