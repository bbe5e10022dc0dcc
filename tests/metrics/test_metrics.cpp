#include <catch2/catch.hpp>
#include <fstream>

#include "metrics/metrics.hpp"
#include "support/test_env.hpp"

using namespace th::metrics;

TEST_CASE("SSIM and PSNR equal scikit-image and numpy on random images and crops",
          "[metrics][python]") {
  const auto dir = th::test::scratch_dir("ssim_skimage");
  torch::manual_seed(11);
  std::vector<std::pair<torch::Tensor, torch::Tensor>> pairs;
  const std::vector<std::pair<int, int>> sizes = {{7, 7}, {20, 33}, {64, 48}, {128, 97}};
  std::ofstream list(dir / "pairs.txt");
  for (size_t i = 0; i < sizes.size(); ++i) {
    const auto [h, w] = sizes[i];
    auto a = torch::rand({h, w, 3}, torch::kFloat64);
    // Correlated prediction with black outside a random valid region, as in evaluation.
    auto b = (a + 0.1 * torch::randn({h, w, 3}, torch::kFloat64)).clamp(0, 1);
    auto valid = torch::rand({h, w}) > 0.2;
    auto c = crop_to_valid(b, a, valid);
    pairs.emplace_back(c.pred, c.gt);
    list << c.pred.size(0) << ' ' << c.pred.size(1) << '\n';
    std::ofstream(dir / ("a_" + std::to_string(i) + ".bin"), std::ios::binary)
        .write(static_cast<const char*>(c.pred.data_ptr()), c.pred.numel() * 8);
    std::ofstream(dir / ("b_" + std::to_string(i) + ".bin"), std::ios::binary)
        .write(static_cast<const char*>(c.gt.data_ptr()), c.gt.numel() * 8);
  }
  list.close();
  REQUIRE(th::test::run_python("tests/python/ssim_reference.py", dir.string()) == 0);
  std::ifstream in(dir / "ssim.txt");
  for (const auto& [a, b] : pairs) {
    double ref_ssim, ref_psnr;
    in >> ref_ssim >> ref_psnr;
    CHECK(std::abs(ssim(a, b) - ref_ssim) < 1e-6);
    CHECK(std::abs(psnr(a.reshape({-1, 3}), b.reshape({-1, 3})) - ref_psnr) < 1e-9);
  }
}

TEST_CASE("SSIM of an image with itself is 1 and drops with noise", "[metrics]") {
  auto a = torch::rand({32, 32, 3}, torch::kFloat64);
  CHECK(ssim(a, a) == Approx(1.0).margin(1e-12));
  CHECK(ssim(a, (a + 0.2 * torch::randn_like(a)).clamp(0, 1)) < 0.95);
}

TEST_CASE("the protocol crop blacks out invalid pixels and keeps the bounding rectangle",
          "[metrics]") {
  auto img = torch::ones({10, 12, 3});
  auto valid = torch::zeros({10, 12}, torch::kBool);
  valid.index_put_({torch::indexing::Slice(2, 5), torch::indexing::Slice(3, 9)}, true);
  valid.index_put_({4, 3}, false);
  const auto c = crop_to_valid(img, img, valid);
  CHECK(c.pred.sizes() == torch::IntArrayRef({3, 6, 3}));
  CHECK(c.pred[2][0].sum().item<float>() == 0.0f);
  CHECK(c.pred[0][0].sum().item<float>() == 3.0f);
  CHECK_THROWS(crop_to_valid(img, img, torch::zeros({10, 12}, torch::kBool)));
}

TEST_CASE("PSNR is -10 log10 of the mean squared error", "[metrics]") {
  auto a = torch::zeros({100, 3}), b = torch::full({100, 3}, 0.1);
  CHECK(psnr(a, b) == Approx(20.0));
}
