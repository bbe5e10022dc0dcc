// The training loss (METHOD 5): rays back in their patches, black elsewhere; MSE + w * LPIPS.
#include <torch/torch.h>

#include <catch2/catch.hpp>

#include "metrics/lpips.hpp"
#include "train/loss.hpp"

TEST_CASE("the patch canvas holds each ray's colour in its slot and black elsewhere",
          "[train][loss]") {
  const int64_t P = 2, S = 4;
  const auto index =
      torch::tensor({0, 5, 17, 31}, torch::kLong);  // slots of 4 rays in 2 patches of 4 x 4
  const auto rgb = torch::rand({4, 3});
  const auto canvas = th::train::patch_canvas(rgb, index, P, S);  // (P, 3, S, S)
  REQUIRE(canvas.sizes() == torch::IntArrayRef({P, 3, S, S}));
  const auto flat = canvas.permute({0, 2, 3, 1}).reshape({P * S * S, 3});
  CHECK(torch::equal(flat.index_select(0, index), rgb));
  CHECK(flat.abs().sum().item<double>() ==
        Approx(rgb.abs().sum().item<double>()));  // zeros elsewhere
  // Slot 17 is patch 1, row 0, column 1.
  CHECK(torch::equal(canvas.index({1, torch::indexing::Slice(), 0, 1}), rgb[2]));
}

TEST_CASE(
    "the loss is MSE over the patches plus lpips_weight times LPIPS, with gradients to the rays "
    "only",
    "[train][loss]") {
  torch::manual_seed(3);
  const int64_t P = 1, S = 32;
  const auto index = torch::randperm(P * S * S).narrow(0, 0, 700);  // 700 of 1024 pixels rendered
  auto rgb = torch::rand({700, 3}).requires_grad_(true);
  const auto target = torch::rand({P, 3, S, S});

  const auto mse_only = th::train::patch_loss(rgb, index, target, nullptr, 0.1);
  const auto canvas = th::train::patch_canvas(rgb.detach(), index, P, S);
  CHECK(mse_only.mse.item<double>() ==
        Approx((canvas - target).pow(2).mean().item<double>()).epsilon(1e-6));
  CHECK(mse_only.total.item<double>() == mse_only.mse.item<double>());
  CHECK_FALSE(mse_only.perceptual.defined());

  th::metrics::Lpips lpips;  // random weights: the formula, not the metric, is under test
  lpips->eval();
  const auto with = th::train::patch_loss(rgb, index, target, lpips.get(), 0.1);
  const double expected_lpips =
      lpips->forward(canvas * 2 - 1, target * 2 - 1).mean().item<double>();
  CHECK(with.perceptual.item<double>() == Approx(expected_lpips).epsilon(1e-5));
  CHECK(with.total.item<double>() ==
        Approx(with.mse.item<double>() + 0.1 * expected_lpips).epsilon(1e-6));
  with.total.backward();
  REQUIRE(rgb.grad().defined());
  CHECK(rgb.grad().abs().sum().item<double>() > 0);

  // Shapes that do not fit are refused, naming what was expected.
  CHECK_THROWS_WITH(th::train::patch_loss(rgb, index.narrow(0, 0, 10), target, nullptr, 0.1),
                    Catch::Contains("one patch index per ray"));
}
