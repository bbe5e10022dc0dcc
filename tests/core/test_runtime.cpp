#include <catch2/catch.hpp>

#include "core/error.hpp"
#include "core/runtime.hpp"

TEST_CASE("the BLAS LibTorch loaded is identified", "[runtime]") {
  // Touch BLAS through LibTorch so that it is certainly loaded.
  auto a = torch::rand({64, 64});
  (void)torch::mm(a, a);
  const auto info = th::runtime::detect_blas();
  CHECK_FALSE(info.name.empty());
  CHECK_FALSE(info.library.empty());
  // scripts/install-deps.sh installs OpenBLAS; the reference BLAS is the case we warn about.
  CHECK(info.name == "OpenBLAS");
  CHECK_FALSE(info.slow);
}

TEST_CASE("device selection follows the request", "[runtime]") {
  CHECK(th::runtime::select_device("cpu") == torch::Device(torch::kCPU));
  const auto dev = th::runtime::select_device("auto");
  CHECK((dev.is_cpu() || dev.is_cuda()));
  if (!torch::cuda::is_available()) {
    CHECK_THROWS_AS(th::runtime::select_device("cuda"), th::Error);
  }
  CHECK_THROWS_AS(th::runtime::select_device("tpu"), th::Error);
}
