#pragma once
// bf16 <-> fp32 conversions for the CPU kernels that read or write bf16 rows: the same values
// as LibTorch's (c10::BFloat16: round to nearest even, NaN to the quiet NaN 0x7fc0), written as
// integer operations the compiler vectorises.

#include <c10/util/BFloat16.h>

#include <cstdint>
#include <cstring>

namespace th::model::kernels {

inline __attribute__((always_inline)) uint16_t bf16_bits(float f) {
  uint32_t u;
  std::memcpy(&u, &f, sizeof u);
  if (f != f) return 0x7fc0;
  return static_cast<uint16_t>((u + 0x7fffu + ((u >> 16) & 1u)) >> 16);
}

inline __attribute__((always_inline)) float bf16_value(uint16_t b) {
  const uint32_t u = uint32_t(b) << 16;
  float f;
  std::memcpy(&f, &u, sizeof f);
  return f;
}

// out[i] = bf16(in[i]) and out[i] = float(in[i]), i < n, one clone per vector width. (AVX512-BF16's
// conversion instruction measured no faster inside the kernels that call these.)
void to_bf16(c10::BFloat16* out, const float* in, int64_t n);
void from_bf16(float* out, const c10::BFloat16* in, int64_t n);

}  // namespace th::model::kernels
