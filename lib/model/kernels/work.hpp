#pragma once
// The work of the per-point operations, counted where they run, for the benchmarks' roofline
// (render::count_work: floating-point operations of the running form, compulsory traffic).

#include <torch/types.h>

#include "render/volume.hpp"

namespace th::model::kernels {

inline double bytes_of(const torch::Tensor& t) {
  return t.defined() ? double(t.numel()) * double(t.element_size()) : 0.0;
}

// An elementwise pass that reads `reads` tensors the size of `out` and writes `out`, `flops` per
// element.
inline void count_elementwise(const torch::Tensor& out, int reads, double flops = 1) {
  render::count_work(flops * double(out.numel()), bytes_of(out) * (reads + 1));
}

// A conversion of `from` to another type: a read of `from`, a write of `to`.
inline void count_conversion(const torch::Tensor& from, const torch::Tensor& to) {
  render::count_work(0, bytes_of(from) + bytes_of(to));
}

// A product y = x w^T (+ b): 2 M K N operations (M N more with a bias), x, w, b read, y written.
inline void count_product(const torch::Tensor& x, const torch::Tensor& w, const torch::Tensor& b,
                          const torch::Tensor& y) {
  const double K = double(w.size(-1)), N = double(w.size(0)), M = double(y.numel()) / N;
  render::count_work(2 * M * K * N + (b.defined() ? M * N : 0),
                     bytes_of(x) + bytes_of(w) + bytes_of(b) + bytes_of(y));
}

}  // namespace th::model::kernels
