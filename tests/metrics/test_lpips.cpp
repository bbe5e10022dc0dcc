#include <catch2/catch.hpp>

#include "core/error.hpp"
#include "io/npy.hpp"
#include "metrics/lpips.hpp"
#include "support/test_env.hpp"

using namespace th::metrics;

TEST_CASE("LPIPS equals the Python formula on torchvision's VGG16 with random weights",
          "[lpips][python]") {
  const auto dir = th::test::scratch_dir("lpips_reference");
  REQUIRE(th::test::run_python("tests/python/lpips_reference.py", dir.string()) == 0);
  Lpips lpips;
  lpips->load(dir / "lpips_random.npz");
  const auto a = th::io::read_npy(dir / "a.npy"), b = th::io::read_npy(dir / "b.npy");
  const auto expected = th::io::read_npy(dir / "dist.npy");
  torch::NoGradGuard g;
  const auto got = lpips->forward(a, b);
  INFO("C++ " << got << " Python " << expected);
  CHECK(torch::allclose(got, expected, 1e-5, 1e-5));
  CHECK(lpips->forward(a, a).abs().max().item<float>() < 1e-6);
}

TEST_CASE("LPIPS weights with a missing or mis-shaped key fail naming it", "[lpips]") {
  const auto dir = th::test::scratch_dir("lpips_bad");
  std::map<std::string, torch::Tensor> arrays{{"features.0.weight", torch::zeros({64, 3, 3, 3})}};
  th::io::write_npz(dir / "partial.npz", arrays);
  Lpips lpips;
  CHECK_THROWS_WITH(lpips->load(dir / "partial.npz"), Catch::Contains("features.0.bias"));
  arrays["features.0.weight"] = torch::zeros({64, 3, 5, 5});
  th::io::write_npz(dir / "shape.npz", arrays);
  CHECK_THROWS_WITH(lpips->load(dir / "shape.npz"),
                    Catch::Contains("'features.0.weight' has shape"));
  CHECK(try_load_lpips("", torch::kCPU, "the LPIPS metric") == nullptr);
  CHECK(try_load_lpips((dir / "nope.npz").string(), torch::kCPU, "the LPIPS metric") == nullptr);
}
