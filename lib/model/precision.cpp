#include "model/precision.hpp"

#include <ATen/Context.h>
#include <spdlog/spdlog.h>
#include <torch/torch.h>

#include <algorithm>

#include "core/error.hpp"
#include "core/runtime.hpp"
#include "core/torch_compat.hpp"
#include "model/kernels/onednn_linear.hpp"
#include "model/kernels/work.hpp"

namespace th::model {

namespace F = torch::nn::functional;

bool onednn_products_agree() {
  static const bool agree = [] {
    if (!at::hasMKLDNN()) return false;
    torch::NoGradGuard no_grad;
    // Fixed values (the global generator is not touched): 300 rows, 64 -> 96, with a bias.
    const auto x = ((torch::arange(300 * 64) % 17) - 8).to(torch::kFloat).div(8).reshape({300, 64});
    const auto w = ((torch::arange(96 * 64) % 13) - 6).to(torch::kFloat).div(13).reshape({96, 64});
    const auto b = torch::arange(96).to(torch::kFloat).div(96);
    const auto ref = F::linear(x, w, b);
    const double err = (kernels::onednn_linear(x, w, b) - ref).abs().max().item<double>();
    return err <= 1e-5 * std::max(1.0, ref.abs().max().item<double>());
  }();
  return agree;
}

torch::Tensor Products::linear(const torch::Tensor& x, const torch::Tensor& w,
                               const torch::Tensor& b) const {
  if (bf16()) {
    const auto t = torch::kBFloat16;
    const auto xb = x.to(t), wb = w.to(t);
    if (x.scalar_type() != t) kernels::count_conversion(x, xb);
    kernels::count_conversion(w, wb);
    const int64_t in = xb.size(-1), rows = in > 0 ? xb.numel() / in : 0;
    torch::Tensor y, bias = b;
    if (onednn && kernels::onednn_bf16() && rows >= kOneDnnMinRows && xb.device().is_cpu()) {
      // oneDNN's primitive: fp32 accumulation, the bias added in fp32, y rounded once
      auto sizes = xb.sizes().vec();
      sizes.back() = w.size(0);
      y = kernels::onednn_linear(xb.reshape({rows, in}), wb, b).view(sizes);
    } else {
      bias = b.defined() ? b.to(t) : b;
      kernels::count_conversion(b, bias);
      y = F::linear(xb, wb, bias);
    }
    kernels::count_product(xb, wb, bias, y);
    return y;
  }
  return linear_fp32(x, w, b);
}

torch::Tensor Products::linear_fp32(const torch::Tensor& x, const torch::Tensor& w,
                                    const torch::Tensor& b) const {
  const auto xf = fp32(x);
  const int64_t in = xf.size(-1), rows = in > 0 ? xf.numel() / in : 0;
  torch::Tensor y;
  if (!onednn || rows < kOneDnnMinRows || xf.scalar_type() != torch::kFloat) {
    y = F::linear(xf, w, b);
  } else {
    auto sizes = xf.sizes().vec();
    sizes.back() = w.size(0);
    y = kernels::onednn_linear(xf.reshape({rows, in}), w, b).view(sizes);
  }
  kernels::count_product(xf, w, b, y);
  return y;
}

torch::Tensor Products::fp32(const torch::Tensor& x) {
  const auto t = x.scalar_type();
  if (t != torch::kBFloat16 && t != torch::kHalf) return x;
  auto y = x.to(torch::kFloat);
  kernels::count_conversion(x, y);
  return y;
}

std::string Products::describe() const {
  if (bf16()) return "bf16 (bf16 products, fp32 elsewhere)";
  return onednn ? "fp32 (oneDNN products)" : "fp32 (BLAS products)";
}

Products resolve_products(PrecisionChoice precision, Fp32Products backend,
                          const torch::Device& device, std::string* why, std::string* warning) {
  const bool cpu = device.is_cpu();
  if (backend == Fp32Products::onednn && cpu && !at::hasMKLDNN())
    fail("fp32_products 'onednn': the linked LibTorch is built without oneDNN (use auto or blas)");
  if (backend == Fp32Products::onednn && cpu && !onednn_products_agree())
    fail(
        "fp32_products 'onednn': this LibTorch's oneDNN product (mkldnn_linear) disagrees with "
        "BLAS on a ",
        "probe product (use auto or blas)");
  Products p;
  p.onednn = cpu && backend != Fp32Products::blas && at::hasMKLDNN() && onednn_products_agree();
  const bool onednn_refused =
      cpu && backend == Fp32Products::automatic && at::hasMKLDNN() && !p.onednn;
  const auto bf16 = runtime::detect_cpu_bf16();
  std::string reason;
  if (precision == PrecisionChoice::fp32) {
    reason = "precision: fp32";
  } else if (precision == PrecisionChoice::bf16) {
    p.precision = Precision::bf16;
    reason = "precision: bf16";
    if (cpu && !bf16.native() && warning)
      *warning = "precision: bf16 on a processor without native bf16 dot products (" +
                 bf16.describe() + "): the products are emulated and run slower than fp32";
  } else if (!cpu) {
    reason =
        "precision: auto on " + device.str() + " keeps fp32 (set precision: bf16 for autocast)";
  } else if (bf16.native()) {
    p.precision = Precision::bf16;
    reason = "precision: auto -> bf16: the processor has " + bf16.describe();
  } else {
    reason = "precision: auto -> fp32: the processor has " + bf16.describe() +
             ", no native bf16 dot products";
  }
  if (why)
    *why =
        reason + " | " + p.describe() +
        (onednn_refused
             ? " (oneDNN's mkldnn_linear disagrees with BLAS on a probe product in this LibTorch)"
             : "");
  return p;
}

Products select_products(PrecisionChoice precision, Fp32Products fp32_products,
                         const torch::Device& device) {
  std::string why, warning;
  const auto p = resolve_products(precision, fp32_products, device, &why, &warning);
  spdlog::info("{}", why);
  if (!warning.empty()) spdlog::warn("{}", warning);
  return p;
}

FrameAutocast::FrameAutocast(const Products& products, const torch::Device& device)
    : active_(products.bf16()), cuda_(device.is_cuda()) {
  if (!active_) return;
  was_enabled_ = compat::autocast_enabled(cuda_);
  previous_dtype_ = compat::autocast_dtype(cuda_);
  compat::set_autocast_enabled(cuda_, true);
  compat::set_autocast_dtype(cuda_, torch::kBFloat16);
  at::autocast::increment_nesting();
}

FrameAutocast::~FrameAutocast() {
  if (!active_) return;
  if (at::autocast::decrement_nesting() == 0) at::autocast::clear_cache();
  compat::set_autocast_enabled(cuda_, was_enabled_);
  compat::set_autocast_dtype(cuda_, previous_dtype_);
}

}  // namespace th::model
