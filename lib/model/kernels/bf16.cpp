#include "model/kernels/bf16.hpp"

namespace th::model::kernels {

__attribute__((target_clones("avx512f", "avx2", "default"))) void to_bf16(c10::BFloat16* out,
                                                                          const float* in,
                                                                          int64_t n) {
  auto* __restrict o = reinterpret_cast<uint16_t*>(out);
  const float* __restrict x = in;
  for (int64_t i = 0; i < n; ++i) o[i] = bf16_bits(x[i]);
}

__attribute__((target_clones("avx512f", "avx2", "default"))) void from_bf16(float* out,
                                                                            const c10::BFloat16* in,
                                                                            int64_t n) {
  float* __restrict o = out;
  const auto* __restrict x = reinterpret_cast<const uint16_t*>(in);
  for (int64_t i = 0; i < n; ++i) o[i] = bf16_value(x[i]);
}

}  // namespace th::model::kernels
