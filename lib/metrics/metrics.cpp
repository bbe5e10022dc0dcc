#include "metrics/metrics.hpp"

#include <torch/torch.h>

#include <cmath>

#include "core/error.hpp"

namespace th::metrics {
namespace F = torch::nn::functional;
using torch::indexing::Slice;

double psnr(const torch::Tensor& pred, const torch::Tensor& gt) {
  TORCH_CHECK(pred.sizes() == gt.sizes(), "psnr: pred ", pred.sizes(), " and gt ", gt.sizes(),
              " differ in shape");
  const double mse =
      (pred.to(torch::kFloat64) - gt.to(torch::kFloat64)).pow(2).mean().item<double>();
  return -10.0 * std::log10(mse);
}

double ssim(const torch::Tensor& a, const torch::Tensor& b, double data_range) {
  TORCH_CHECK(a.dim() == 3 && a.sizes() == b.sizes(),
              "ssim: images must be (H, W, C) of one shape");
  const int win = 7;
  TORCH_CHECK(a.size(0) >= win && a.size(1) >= win, "ssim: images smaller than the 7x7 window (",
              a.sizes(), ")");
  // (C, 1, H, W) float64; average pooling without padding gives exactly the window means of
  // the pixels that the 3-pixel crop keeps, so scikit-image's border padding never matters.
  const auto x = a.to(torch::kFloat64).permute({2, 0, 1}).unsqueeze(1);
  const auto y = b.to(torch::kFloat64).permute({2, 0, 1}).unsqueeze(1);
  auto mean = [&](const torch::Tensor& t) {
    return F::avg_pool2d(t, F::AvgPool2dFuncOptions(win).stride(1));
  };
  const double np = win * win, cov_norm = np / (np - 1.0);
  const auto ux = mean(x), uy = mean(y);
  const auto vx = cov_norm * (mean(x * x) - ux * ux);
  const auto vy = cov_norm * (mean(y * y) - uy * uy);
  const auto vxy = cov_norm * (mean(x * y) - ux * uy);
  const double c1 = std::pow(0.01 * data_range, 2), c2 = std::pow(0.03 * data_range, 2);
  const auto s =
      ((2 * ux * uy + c1) * (2 * vxy + c2)) / ((ux * ux + uy * uy + c1) * (vx + vy + c2));
  return s.mean({1, 2, 3}).mean().item<double>();  // per channel, then over channels
}

Crop crop_to_valid(const torch::Tensor& pred, const torch::Tensor& gt, const torch::Tensor& valid) {
  TORCH_CHECK(valid.dim() == 2 && pred.dim() == 3 && pred.sizes() == gt.sizes() &&
                  pred.size(0) == valid.size(0) && pred.size(1) == valid.size(1),
              "crop_to_valid: pred/gt (H, W, 3) and valid (H, W) must agree");
  const auto m = valid.to(torch::kBool);
  const auto rows = m.any(1).nonzero(), cols = m.any(0).nonzero();
  if (rows.numel() == 0) fail("no valid pixels to evaluate (the body box is not in the image)");
  const int64_t y0 = rows.min().item<int64_t>(), y1 = rows.max().item<int64_t>() + 1;
  const int64_t x0 = cols.min().item<int64_t>(), x1 = cols.max().item<int64_t>() + 1;
  const auto keep = m.unsqueeze(-1);
  return {(pred * keep).index({Slice(y0, y1), Slice(x0, x1)}).contiguous(),
          (gt * keep).index({Slice(y0, y1), Slice(x0, x1)}).contiguous()};
}

}  // namespace th::metrics
