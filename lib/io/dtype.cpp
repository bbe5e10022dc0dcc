#include "io/dtype.hpp"

#include <cstring>

#include "core/error.hpp"

namespace th::io::detail {

std::string NpyDType::descr() const {
  if (is_object()) return "|O";
  return std::string(1, order) + kind + std::to_string(size);
}

std::string NpyDType::code() const { return std::string(1, kind) + std::to_string(size); }

std::string NpyDType::name() const {
  switch (kind) {
    case 'f':
      return "float" + std::to_string(size * 8);
    case 'i':
      return "int" + std::to_string(size * 8);
    case 'u':
      return "uint" + std::to_string(size * 8);
    case 'b':
      return "bool";
    default:
      return "object";
  }
}

torch::ScalarType NpyDType::scalar_type() const {
  switch (kind) {
    case 'f':
      return size == 2 ? torch::kHalf : size == 4 ? torch::kFloat : torch::kDouble;
    case 'i':
      return size == 1   ? torch::kChar
             : size == 2 ? torch::kShort
             : size == 4 ? torch::kInt
                         : torch::kLong;
    case 'u':
      return size == 1 ? torch::kByte : size == 2 ? torch::kInt : torch::kLong;
    case 'b':
      return torch::kBool;
    default:
      TORCH_CHECK(false, "object dtype has no tensor type");
  }
}

std::optional<NpyDType> parse_dtype(std::string_view text) {
  NpyDType dt;
  char order = '=';
  if (!text.empty() && (text[0] == '<' || text[0] == '>' || text[0] == '|' || text[0] == '=')) {
    order = text[0];
    text.remove_prefix(1);
  }
  if (text.empty()) return std::nullopt;
  if (text.size() == 1) {
    // numpy's one-letter type codes.
    switch (text[0]) {
      case '?':
        dt.kind = 'b', dt.size = 1;
        break;
      case 'b':
        dt.kind = 'i', dt.size = 1;
        break;
      case 'B':
        dt.kind = 'u', dt.size = 1;
        break;
      case 'h':
        dt.kind = 'i', dt.size = 2;
        break;
      case 'H':
        dt.kind = 'u', dt.size = 2;
        break;
      case 'i':
        dt.kind = 'i', dt.size = 4;
        break;
      case 'I':
        dt.kind = 'u', dt.size = 4;
        break;
      case 'l':
      case 'q':
        dt.kind = 'i', dt.size = 8;
        break;
      case 'e':
        dt.kind = 'f', dt.size = 2;
        break;
      case 'f':
        dt.kind = 'f', dt.size = 4;
        break;
      case 'd':
        dt.kind = 'f', dt.size = 8;
        break;
      case 'O':
        dt.kind = 'O', dt.size = 8;
        break;
      default:
        return std::nullopt;
    }
  } else {
    dt.kind = text[0];
    const std::string_view digits = text.substr(1);
    if (digits.size() > 2) return std::nullopt;
    int size = 0;
    for (char c : digits) {
      if (c < '0' || c > '9') return std::nullopt;
      size = size * 10 + (c - '0');
    }
    dt.size = size;
    bool ok = false;
    switch (dt.kind) {
      case 'f':
        ok = size == 2 || size == 4 || size == 8;
        break;
      case 'i':
        ok = size == 1 || size == 2 || size == 4 || size == 8;
        break;
      case 'u':
        ok = size == 1 || size == 2 || size == 4;
        break;
      case 'b':
        ok = size == 1;
        break;
      case 'O':
        ok = size == 8;
        break;
      default:
        break;
    }
    if (!ok) return std::nullopt;
  }
  if (dt.size == 1 || dt.is_object()) {
    dt.order = '|';
  } else {
    dt.order = (order == '>') ? '>' : '<';
  }
  return dt;
}

NpyDType dtype_of(torch::ScalarType type) {
  switch (type) {
    case torch::kFloat:
      return {'<', 'f', 4};
    case torch::kDouble:
      return {'<', 'f', 8};
    case torch::kHalf:
      return {'<', 'f', 2};
    case torch::kChar:
      return {'|', 'i', 1};
    case torch::kShort:
      return {'<', 'i', 2};
    case torch::kInt:
      return {'<', 'i', 4};
    case torch::kLong:
      return {'<', 'i', 8};
    case torch::kByte:
      return {'|', 'u', 1};
    case torch::kBool:
      return {'|', 'b', 1};
    default:
      th::fail("numpy has no dtype for tensors of type ", c10::toString(type));
  }
}

std::optional<int64_t> element_count(const std::vector<int64_t>& shape) {
  int64_t count = 1;
  bool zero = false;
  for (int64_t d : shape) {
    if (d < 0 || d > kMaxElements) return std::nullopt;
    if (d == 0) zero = true;
    if (!zero) {
      if (count > kMaxElements / std::max<int64_t>(d, 1)) return std::nullopt;
      count *= d;
    }
  }
  return zero ? 0 : count;
}

torch::Tensor decode_array(std::string_view bytes, const NpyDType& dtype,
                           const std::vector<int64_t>& shape, bool fortran) {
  const auto count = element_count(shape);
  TORCH_CHECK(
      count && !dtype.is_object() && static_cast<uint64_t>(*count) * dtype.size == bytes.size(),
      "decode_array: byte count does not match the shape");
  const torch::ScalarType raw_type = dtype.kind == 'b'                      ? torch::kByte
                                     : dtype.kind == 'u' && dtype.size == 2 ? torch::kShort
                                     : dtype.kind == 'u' && dtype.size == 4 ? torch::kInt
                                                                            : dtype.scalar_type();
  torch::Tensor flat = torch::empty({*count}, torch::TensorOptions().dtype(raw_type));
  if (!bytes.empty()) std::memcpy(flat.data_ptr(), bytes.data(), bytes.size());
  if (dtype.order == '>' && dtype.size > 1 && *count > 0) {
    flat = flat.view(torch::kByte)
               .view({*count, dtype.size})
               .flip({1})
               .contiguous()
               .view(raw_type)
               .view({*count});
  }
  if (dtype.kind == 'b') {
    flat = flat.ne(0);
  } else if (dtype.kind == 'u' && dtype.size == 2) {
    flat = flat.to(torch::kInt).bitwise_and(0xffff);
  } else if (dtype.kind == 'u' && dtype.size == 4) {
    flat = flat.to(torch::kLong).bitwise_and(int64_t{0xffffffff});
  }
  if (fortran && shape.size() > 1) {
    std::vector<int64_t> reversed(shape.rbegin(), shape.rend());
    std::vector<int64_t> order(shape.size());
    for (size_t i = 0; i < shape.size(); ++i) order[i] = static_cast<int64_t>(shape.size() - 1 - i);
    return flat.view(reversed).permute(order).contiguous();
  }
  return flat.view(shape);
}

std::string encode_array(const torch::Tensor& array) {
  dtype_of(array.scalar_type());  // refuses types numpy lacks
  const torch::Tensor t = array.is_contiguous() ? array : array.contiguous();
  std::string out(static_cast<size_t>(t.numel()) * t.element_size(), '\0');
  if (!out.empty()) std::memcpy(out.data(), t.data_ptr(), out.size());
  return out;
}

}  // namespace th::io::detail
