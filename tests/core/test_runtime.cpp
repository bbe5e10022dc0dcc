#include <catch2/catch.hpp>

#include "core/error.hpp"
#include "core/resources.hpp"
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

TEST_CASE("the project's own kernels run on every LibTorch thread", "[runtime]") {
  // Fails when lib/ is compiled without OpenMP: at::parallel_for then runs on one thread.
  const int before = torch::get_num_threads();
  torch::set_num_threads(2);
  CHECK(th::runtime::parallel_for_threads(64) == 2);
  torch::set_num_threads(1);
  CHECK(th::runtime::parallel_for_threads(64) == 1);
  torch::set_num_threads(before);
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

TEST_CASE("absurd thread counts are refused before any thread is made", "[runtime]") {
  const int before = torch::get_num_threads();
  CHECK_THROWS_WITH(th::runtime::set_threads(100000),
                    Catch::Contains("threads=100000") && Catch::Contains("per core"));
  CHECK(torch::get_num_threads() == before);
}

TEST_CASE("resource estimates are printed and refused above max_memory_gb", "[runtime]") {
  th::resources::Estimate e;
  e.what = "mesh grid 7145 x 4892 x 19524";
  e.bytes = 3.0 * (1 << 30);
  e.samples = 6.8e11;
  e.threads = 2;
  CHECK_NOTHROW(th::resources::check(e, 4));
  CHECK_THROWS_WITH(th::resources::check(e, 2), Catch::Contains("mesh grid 7145 x 4892 x 19524") &&
                                                    Catch::Contains("3.0 GiB") &&
                                                    Catch::Contains("max_memory_gb=2"));
  CHECK_THROWS_WITH(th::resources::check(e, -1), Catch::Contains("max_memory_gb must be >= 0"));
  CHECK(th::resources::memory_limit_bytes(0) > 0);
  CHECK(th::resources::memory_limit_bytes(0) <= double(th::resources::physical_memory_bytes()));
  CHECK(th::resources::bytes_text(512.0 * (1 << 20)) == "512 MiB");
}
