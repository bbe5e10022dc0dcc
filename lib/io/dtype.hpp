#pragma once
// numpy dtypes <-> torch scalar types, and raw array bytes <-> tensors (METHOD 1.4). Internal to
// lib/io: shared by the .npy reader/writer and the pickle reader/writer.

#include <torch/types.h>

#include <cstdint>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

namespace th::io::detail {

// No array may claim more elements than this (absurd shapes are refused before allocating).
constexpr int64_t kMaxElements = int64_t{1} << 40;

struct NpyDType {
  char order = '<';  // '<' little, '>' big, '|' not applicable (1-byte types, objects)
  char kind = 'f';   // 'f' float, 'i' signed, 'u' unsigned, 'b' bool, 'O' Python object
  int size = 8;      // bytes per element

  bool is_object() const { return kind == 'O'; }
  std::string descr() const;  // "<f8", "|u1", "|O" (the .npy header's 'descr')
  std::string code() const;   // "f8", "O8" (what numpy.dtype's pickle passes to the constructor)
  std::string name() const;   // "float64", "uint8", "object" (for messages)
  // Tensor type the data is read into (u2 and u4 widen to Int and Long; b1 reads as Bool).
  torch::ScalarType scalar_type() const;
};

// "<f8", "|b1", ">i4", "f8", "O8", "|O", "?", "d", ...; nullopt when the dtype is not one of
// f2 f4 f8 i1 i2 i4 i8 u1 u2 u4 b1 O. '=' and a missing byte order mean little endian.
std::optional<NpyDType> parse_dtype(std::string_view text);
// The dtype numpy uses for a tensor of this type; throws th::Error for types numpy lacks.
NpyDType dtype_of(torch::ScalarType type);

// Product of `shape`; nullopt when a dimension is negative or the product (or a dimension)
// exceeds kMaxElements.
std::optional<int64_t> element_count(const std::vector<int64_t>& shape);

// A C-contiguous tensor from raw array bytes, which must hold exactly element_count(shape) *
// dtype.size bytes in C (or, with `fortran`, Fortran) order. One memcpy for native data.
torch::Tensor decode_array(std::string_view bytes, const NpyDType& dtype,
                           const std::vector<int64_t>& shape, bool fortran);
// numpy's tobytes(): C order, little endian, bools as 0/1 bytes.
std::string encode_array(const torch::Tensor& array);

}  // namespace th::io::detail
