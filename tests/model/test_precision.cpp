// Mixed precision: what the processor offers, how a setting resolves, and the products
// themselves against a float64 reference.
#include <torch/torch.h>

#include <catch2/catch.hpp>
#include <cmath>
#include <fstream>
#include <set>
#include <sstream>
#include <tuple>

#include "core/config.hpp"
#include "core/config_io.hpp"
#include "core/error.hpp"
#include "core/runtime.hpp"
#include "core/torch_compat.hpp"
#include "model/kernels/onednn_linear.hpp"
#include "model/precision.hpp"

using th::model::FrameAutocast;
using th::model::Precision;
using th::model::Products;
using th::model::resolve_products;

namespace {

// The flags of the first processor in /proc/cpuinfo.
std::set<std::string> cpu_flags() {
  std::ifstream in("/proc/cpuinfo");
  std::string line;
  std::set<std::string> flags;
  while (std::getline(in, line)) {
    if (line.rfind("flags", 0) != 0) continue;
    std::istringstream words(line.substr(line.find(':') + 1));
    for (std::string w; words >> w;) flags.insert(w);
    break;
  }
  return flags;
}

double max_rel(const torch::Tensor& a, const torch::Tensor& ref) {
  return ((a.to(torch::kDouble) - ref).abs().max() / ref.abs().max()).item<double>();
}

}  // namespace

TEST_CASE("the bf16 instructions found by CPUID are the ones the kernel reports", "[precision]") {
  const auto flags = cpu_flags();
  if (flags.empty()) {
    WARN("no flags line in /proc/cpuinfo: nothing to compare with");
    return;
  }
  const auto c = th::runtime::detect_cpu_bf16();
  CHECK(c.avx512_bf16 == (flags.count("avx512_bf16") == 1));
  CHECK(c.amx_bf16 == (flags.count("amx_bf16") == 1));
  CHECK(c.avx512 == (flags.count("avx512f") && flags.count("avx512bw") && flags.count("avx512vl")));
  CHECK(c.native() == (c.avx512_bf16 || c.amx_bf16));
}

TEST_CASE("precision auto takes bf16 exactly where the processor has native bf16 dot products",
          "[precision]") {
  std::string why, warning;
  const auto p = resolve_products(th::PrecisionChoice::automatic, th::Fp32Products::automatic,
                                  torch::kCPU, &why, &warning);
  const bool native = th::runtime::detect_cpu_bf16().native();
  CHECK(p.bf16() == native);
  CHECK(why.find(native ? "auto -> bf16" : "auto -> fp32") != std::string::npos);
  CHECK(warning.empty());
  CHECK(!resolve_products(th::PrecisionChoice::fp32, th::Fp32Products::automatic, torch::kCPU)
             .bf16());
  CHECK(resolve_products(th::PrecisionChoice::bf16, th::Fp32Products::automatic, torch::kCPU, &why,
                         &warning)
            .bf16());
  CHECK(warning.empty() == native);  // explicit bf16 without native products warns
  CHECK(resolve_products(th::PrecisionChoice::fp32, th::Fp32Products::blas, torch::kCPU).onednn ==
        false);
  CHECK(resolve_products(th::PrecisionChoice::fp32, th::Fp32Products::automatic, torch::kCPU)
            .onednn == th::model::onednn_products_agree());
}

TEST_CASE("bad precision values are refused by name", "[precision]") {
  auto message = [](auto&& fn) {
    try {
      fn();
    } catch (const th::Error& e) {
      return std::string(e.what());
    }
    return std::string("(no error)");
  };
  const auto m =
      message([] { th::config::load<th::Config>("configs/default.yaml", {"precision=half"}); });
  CHECK(m.find("'precision'") != std::string::npos);
  CHECK(m.find("half") != std::string::npos);
  const auto n =
      message([] { th::config::load<th::Config>("configs/default.yaml", {"fp32_products=gpu"}); });
  CHECK(n.find("'fp32_products'") != std::string::npos);
  CHECK(n.find("gpu") != std::string::npos);
}

TEST_CASE("products match a float64 reference: fp32 to 1e-6, bf16 to 2e-2, gradients included",
          "[precision]") {
  torch::manual_seed(0);
  const auto x = torch::randn({1000, 3, 64}), w = torch::randn({96, 64}) * 0.1,
             b = torch::randn({96});
  const auto ref = torch::nn::functional::linear(x.to(torch::kDouble), w.to(torch::kDouble),
                                                 b.to(torch::kDouble));
  std::vector<std::pair<const char*, Products>> paths{
      {"blas", resolve_products(th::PrecisionChoice::fp32, th::Fp32Products::blas, torch::kCPU)},
      {"bf16",
       resolve_products(th::PrecisionChoice::bf16, th::Fp32Products::automatic, torch::kCPU)}};
  // Where oneDNN's product is wrong (Debian 13's LibTorch 2.6), it is refused, and auto takes BLAS.
  if (th::model::onednn_products_agree()) {
    paths.emplace_back("onednn", resolve_products(th::PrecisionChoice::fp32,
                                                  th::Fp32Products::onednn, torch::kCPU));
  } else {
    CHECK_THROWS_WITH(
        resolve_products(th::PrecisionChoice::fp32, th::Fp32Products::onednn, torch::kCPU),
        Catch::Contains("disagrees with BLAS on a probe product"));
    CHECK_FALSE(
        resolve_products(th::PrecisionChoice::fp32, th::Fp32Products::automatic, torch::kCPU)
            .onednn);
  }
  for (const auto& [name, p] : paths) {
    CAPTURE(name);
    const double tol = p.bf16() ? 2e-2 : 1e-6;
    const auto y = p.linear(x, w, b);
    CHECK(y.sizes() == ref.sizes());
    CHECK(y.scalar_type() == (p.bf16() ? torch::kBFloat16 : torch::kFloat));
    CHECK(max_rel(y, ref) < tol);
    // Gradients of a weighted sum, against float64 autograd.
    const auto g = torch::randn_like(ref);
    auto xd = x.to(torch::kDouble).requires_grad_(), wd = w.to(torch::kDouble).requires_grad_(),
         bd = b.to(torch::kDouble).requires_grad_();
    (torch::nn::functional::linear(xd, wd, bd) * g).sum().backward();
    auto xf = x.clone().requires_grad_(), wf = w.clone().requires_grad_(),
         bf = b.clone().requires_grad_();
    (Products::fp32(p.linear(xf, wf, bf)) * g.to(torch::kFloat)).sum().backward();
    REQUIRE(wf.grad().defined());
    CHECK(wf.grad().scalar_type() == torch::kFloat);
    CHECK(max_rel(xf.grad(), xd.grad()) < tol);
    CHECK(max_rel(wf.grad(), wd.grad()) < tol);
    CHECK(max_rel(bf.grad(), bd.grad()) < tol);
    // linear_fp32 without a bias: fp32 whatever the precision, with gradients.
    auto xn = x.clone().requires_grad_(), wn = w.clone().requires_grad_();
    const auto yn = p.linear_fp32(xn, wn);
    CHECK(yn.scalar_type() == torch::kFloat);
    CHECK(max_rel(yn, ref - b.to(torch::kDouble)) < 1e-6);
    (yn * g.to(torch::kFloat)).sum().backward();
    CHECK(max_rel(wn.grad(), wd.grad()) < 1e-6);
    CHECK(max_rel(xn.grad(), xd.grad()) < 1e-6);
  }
}

TEST_CASE("the direct oneDNN product equals LibTorch's mkldnn_linear to the bit", "[precision]") {
  if (!at::hasMKLDNN()) {
    WARN("this LibTorch has no oneDNN: nothing to compare");
    return;
  }
  if (!th::model::kernels::onednn_direct())
    WARN("this build has no oneDNN 2 headers: onednn_linear is mkldnn_linear itself");
  torch::manual_seed(1);
  torch::NoGradGuard no_grad;
  // The model's shapes (rows: points x views, a chunk's remainder), a bias-free product, a
  // non-contiguous input, and no rows at all.
  for (const auto& [rows, in, out] : std::vector<std::tuple<int64_t, int64_t, int64_t>>{
           {12288, 256, 384}, {2777, 256, 128}, {4096, 63, 256}, {5, 27, 1}, {0, 256, 256}}) {
    for (const bool bias : {true, false}) {
      CAPTURE(rows, in, out, bias);
      const auto x = torch::randn({rows, in}), w = torch::randn({out, in}) * 0.1;
      const auto b = bias ? torch::randn({out}) : torch::Tensor();
      const c10::optional<torch::Tensor> ob = bias ? c10::optional<torch::Tensor>(b) : c10::nullopt;
      const auto y = th::model::kernels::onednn_linear(x, w, b);
      REQUIRE(y.sizes() == torch::IntArrayRef{rows, out});
      if (rows == 0) continue;
      const auto ref = at::mkldnn_linear(x.to_mkldnn(), w, ob).to_dense();
      CHECK(torch::equal(y, ref));
      const auto xt = torch::randn({in, rows}).t();  // strided rows
      CHECK(torch::equal(th::model::kernels::onednn_linear(xt, w, b),
                         at::mkldnn_linear(xt.contiguous().to_mkldnn(), w, ob).to_dense()));
      // bf16 operands: the exact product of the bf16 values plus the fp32 bias, rounded once
      // (within one bf16 rounding: the sums run in fp32).
      if (!th::model::kernels::onednn_bf16()) continue;
      const auto xb = x.to(torch::kBFloat16), wb = w.to(torch::kBFloat16);
      const auto yb = th::model::kernels::onednn_linear(xb, wb, b);
      CHECK(yb.scalar_type() == torch::kBFloat16);
      auto exact = torch::mm(xb.to(torch::kDouble), wb.to(torch::kDouble).t());
      if (bias) exact += b.to(torch::kDouble);
      const auto err = (yb.to(torch::kDouble) - exact).abs();
      CHECK((err <= exact.abs() * std::pow(2.0, -8) + 1e-4).all().item<bool>());
    }
  }
}

TEST_CASE("frame autocast runs bf16 convolutions only in its scope and restores the state",
          "[precision]") {
  auto conv = torch::nn::Conv2d(torch::nn::Conv2dOptions(3, 8, 3));
  const auto img = torch::rand({1, 3, 16, 16});
  REQUIRE(!th::compat::autocast_enabled(false));
  {
    FrameAutocast none(
        resolve_products(th::PrecisionChoice::fp32, th::Fp32Products::automatic, torch::kCPU),
        torch::kCPU);
    CHECK(conv->forward(img).scalar_type() == torch::kFloat);
  }
  {
    FrameAutocast bf16(
        resolve_products(th::PrecisionChoice::bf16, th::Fp32Products::automatic, torch::kCPU),
        torch::kCPU);
    CHECK(th::compat::autocast_enabled(false));
    CHECK(conv->forward(img).scalar_type() == torch::kBFloat16);
  }
  CHECK(!th::compat::autocast_enabled(false));
  CHECK(conv->forward(img).scalar_type() == torch::kFloat);
}
