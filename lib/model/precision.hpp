#pragma once
// Mixed precision: which operation of the network runs in which floating-point type. The model's
// Products (TransHumanImpl::set_products) decide it: the per-point stages call Products::linear
// for their products, Products::fp32 where their outputs meet fp32 work, and the definition puts
// FrameAutocast around the per-frame modules.
//
// What runs in which type:
// - per-point products (FDI's key/value projections and fc_2, the density head's fc_3, the
//   colour head's feature product): fp32 through oneDNN or BLAS (below); under bf16, bf16
//   operands, fp32 accumulation and bias, bf16 output (oneDNN's primitive where this build calls
//   it directly, LibTorch's bf16 linear otherwise).
// - the activations that only those products read (Products::between): bf16 under bf16, written
//   so by the kernels that make them (DPaRF's and the appearance readout's gathers, the view
//   attention) after computing them in fp32, and read as bf16 by the kernels after them (the view
//   attention, the heads' view means).
// - the readout windows' tables (model/pixels.hpp): bf16 under bf16, the gathers that read them
//   sum in fp32.
// - per-frame modules (ResNet encoder, TransHE: convolutions, linear layers, attention
//   products): fp32; autocast to bf16 under bf16, outputs cast back to fp32.
// - everything else (positional encodings, DPaRF's distances, nearest fields and weights, the
//   gathers' sums, the view attention's softmax, the heads' means and last layers, compositing,
//   losses, metrics, optimiser state and master weights, checkpoints): fp32.
//
// Weights stay fp32 parameters and are cast per use, so gradients reach fp32 master weights.
//
// fp32 products: oneDNN (a reorder in, the product, a reorder out) runs faster than OpenBLAS
// on the per-point shapes and sums in another order (results differ by float rounding; the
// figures are in docs/PERFORMANCE.md); it is taken for products of at least kOneDnnMinRows rows
// when LibTorch is built with it (`fp32_products: auto`).

#include <torch/types.h>

#include <string>

#include "core/config.hpp"

namespace th::model {

enum class Precision { fp32, bf16 };

// Products of fewer rows than this stay on BLAS (the reorders cost more than they save).
constexpr int64_t kOneDnnMinRows = 256;

struct Products {
  Precision precision = Precision::fp32;
  bool onednn = false;  // fp32 products through oneDNN (CPU only)

  bool bf16() const { return precision == Precision::bf16; }
  // The type of activations that only products read: bf16 under bf16 for fp32 ones (the
  // kernels that make them write bf16 rows), `type` itself otherwise.
  c10::ScalarType between(c10::ScalarType type) const {
    return bf16() && type == c10::ScalarType::Float ? c10::ScalarType::BFloat16 : type;
  }
  // y = x w^T + b: x (..., in) fp32 or bf16, w (out, in) and b (out) fp32 (b may be undefined)
  // -> (..., out) in the compute type (bf16 under bf16). Differentiable in x, w and b. A float64
  // model (gradient checks) computes in float64 under fp32 and never through oneDNN.
  torch::Tensor linear(const torch::Tensor& x, const torch::Tensor& w,
                       const torch::Tensor& b = {}) const;
  // The same in fp32 whatever the precision (the heads' last layers, the small per-point
  // products), through oneDNN when `onednn`: the per-point loop then never wakes BLAS's own
  // thread pool, whose waiting threads would compete with oneDNN's for the cores.
  torch::Tensor linear_fp32(const torch::Tensor& x, const torch::Tensor& w,
                            const torch::Tensor& b = {}) const;
  // x in fp32 when it is bf16 or fp16; fp32 and float64 tensors (gradient checks) unchanged.
  static torch::Tensor fp32(const torch::Tensor& x);
  // "fp32 (oneDNN products)", "bf16" ...
  std::string describe() const;
};

// Whether this LibTorch's oneDNN fp32 product (mkldnn_linear) agrees with BLAS on a fixed probe
// product, to 1e-5 relative; checked once per process. Debian 13's LibTorch 2.6 gives wrong
// results there, so `fp32_products: auto` takes BLAS and `onednn` is refused.
bool onednn_products_agree();

// The products for the config's `precision` (fp32 | bf16 | auto) and `fp32_products`
// (auto | onednn | blas) on `device`. auto takes bf16 where the processor executes bf16 dot
// products natively (AVX512-BF16 or AMX, runtime::detect_cpu_bf16), fp32 elsewhere (on CUDA
// too: bf16 there is asked for by name). `why` (optional) receives one line saying which and why;
// an explicit bf16 on a processor without those instructions runs emulated and `warning` says so.
// `onednn` where this LibTorch lacks oneDNN, or its product disagrees, is a th::Error naming it.
Products resolve_products(PrecisionChoice precision, Fp32Products fp32_products,
                          const torch::Device& device, std::string* why = nullptr,
                          std::string* warning = nullptr);

// resolve_products for the config's keys, with its line logged (and its warning, if any).
Products select_products(PrecisionChoice precision, Fp32Products fp32_products,
                         const torch::Device& device);

// Autocast to bf16 on `device` while alive, when `products` asks for bf16 (the per-frame
// modules); nothing otherwise. Restores the previous autocast state.
class FrameAutocast {
 public:
  FrameAutocast(const Products& products, const torch::Device& device);
  ~FrameAutocast();
  FrameAutocast(const FrameAutocast&) = delete;
  FrameAutocast& operator=(const FrameAutocast&) = delete;

 private:
  bool active_ = false, cuda_ = false, was_enabled_ = false;
  c10::ScalarType previous_dtype_ = c10::ScalarType::Float;
};

}  // namespace th::model
