// .npy (format 1.0/2.0/3.0) and .npz (METHOD 1.4), following numpy 1.24's lib/format.py.
#include "io/npy.hpp"

#include <optional>

#include "core/error.hpp"
#include "io/bytes.hpp"
#include "io/dtype.hpp"
#include "io/pickle_writer.hpp"
#include "io/zip.hpp"

namespace th::io {
namespace {

constexpr std::string_view kMagic = "\x93NUMPY";
constexpr size_t kArrayAlign = 64;        // numpy's ARRAY_ALIGN
constexpr size_t kGrowthAxisDigits = 21;  // numpy's GROWTH_AXIS_MAX_DIGITS

struct Header {
  detail::NpyDType dtype;
  bool fortran = false;
  std::vector<int64_t> shape;
  size_t data_offset = 0;
};

// The header is a Python dict literal: {'descr': '<f8', 'fortran_order': False, 'shape': (2, 3), }
class HeaderParser {
 public:
  HeaderParser(std::string_view text, size_t offset, const std::string& name)
      : s_(text), base_(offset), name_(name) {}

  Header parse() {
    Header h;
    bool have_descr = false, have_order = false, have_shape = false;
    expect('{');
    for (;;) {
      skip_space();
      if (peek() == '}') break;
      const std::string key = string_literal();
      expect(':');
      skip_space();
      if (key == "descr" && !have_descr) {
        if (peek() != '\'' && peek() != '"')
          bad("'descr' is not a string (structured dtypes are not supported)");
        const std::string descr = string_literal();
        const auto dtype = detail::parse_dtype(descr);
        if (!dtype) th::fail(name_, ": unsupported dtype '", descr, "'");
        h.dtype = *dtype;
        have_descr = true;
      } else if (key == "fortran_order" && !have_order) {
        h.fortran = boolean();
        have_order = true;
      } else if (key == "shape" && !have_shape) {
        h.shape = int_tuple();
        have_shape = true;
      } else {
        bad("unexpected key '" + key + "'");
      }
      skip_space();
      if (peek() == ',') {
        ++i_;
      } else if (peek() != '}') {
        bad("expected ',' or '}'");
      }
    }
    if (!have_descr || !have_order || !have_shape)
      bad("missing 'descr', 'fortran_order' or 'shape'");
    return h;
  }

 private:
  [[noreturn]] void bad(const std::string& what) {
    th::fail(name_, ": malformed .npy header: ", what, " at byte ", base_ + i_);
  }
  char peek() const { return i_ < s_.size() ? s_[i_] : '\0'; }
  void skip_space() {
    while (i_ < s_.size() && (s_[i_] == ' ' || s_[i_] == '\t' || s_[i_] == '\n' || s_[i_] == '\r'))
      ++i_;
  }
  void expect(char c) {
    skip_space();
    if (peek() != c) bad(std::string("expected '") + c + "'");
    ++i_;
  }
  std::string string_literal() {
    skip_space();
    const char quote = peek();
    if (quote != '\'' && quote != '"') bad("expected a string");
    const size_t start = ++i_;
    while (i_ < s_.size() && s_[i_] != quote) {
      if (s_[i_] == '\\') bad("escapes in strings are not supported");
      ++i_;
    }
    if (i_ >= s_.size()) bad("unterminated string");
    return std::string(s_.substr(start, i_++ - start));
  }
  bool boolean() {
    if (s_.substr(i_, 4) == "True") {
      i_ += 4;
      return true;
    }
    if (s_.substr(i_, 5) == "False") {
      i_ += 5;
      return false;
    }
    bad("expected True or False");
  }
  std::vector<int64_t> int_tuple() {
    expect('(');
    std::vector<int64_t> out;
    for (;;) {
      skip_space();
      if (peek() == ')') break;
      if (out.size() == 64) bad("too many dimensions");
      int64_t v = 0;
      size_t digits = 0;
      while (i_ < s_.size() && s_[i_] >= '0' && s_[i_] <= '9') {
        if (v > detail::kMaxElements) bad("absurd dimension");
        v = v * 10 + (s_[i_++] - '0');
        ++digits;
      }
      if (digits == 0) bad("expected a non-negative integer");
      if (peek() == 'L') ++i_;  // Python 2 long
      out.push_back(v);
      skip_space();
      if (peek() == ',') {
        ++i_;
      } else if (peek() != ')') {
        bad("expected ',' or ')'");
      }
    }
    ++i_;
    return out;
  }

  std::string_view s_;
  size_t base_;
  const std::string& name_;
  size_t i_ = 0;
};

Header parse_header(std::string_view bytes, const std::string& name) {
  if (bytes.size() < 10 || bytes.substr(0, 6) != kMagic) {
    th::fail(name, ": not a .npy file (no \\x93NUMPY magic at byte 0)");
  }
  const int major = static_cast<uint8_t>(bytes[6]), minor = static_cast<uint8_t>(bytes[7]);
  if ((major != 1 && major != 2 && major != 3) || minor != 0) {
    th::fail(name, ": unsupported .npy format version ", major, ".", minor, " at byte 6");
  }
  const size_t length_size = major == 1 ? 2 : 4;
  if (bytes.size() < 8 + length_size) th::fail(name, ": truncated .npy header at byte 8");
  const uint64_t header_len = detail::load_le(bytes.data() + 8, static_cast<int>(length_size));
  const size_t start = 8 + length_size;
  if (header_len > bytes.size() - start) {
    th::fail(name, ": truncated: the .npy header at byte ", start, " claims ", header_len,
             " bytes, the file has ", bytes.size() - start, " after it");
  }
  Header h =
      HeaderParser(bytes.substr(start, static_cast<size_t>(header_len)), start, name).parse();
  if (!detail::element_count(h.shape)) {
    th::fail(name, ": absurd array shape ", detail::shape_repr(h.shape),
             " (more than 2^40 elements)");
  }
  h.data_offset = start + static_cast<size_t>(header_len);
  return h;
}

torch::Tensor numeric_data(std::string_view bytes, const Header& h, const std::string& name) {
  const int64_t count = *detail::element_count(h.shape);
  const uint64_t needed = static_cast<uint64_t>(count) * static_cast<uint64_t>(h.dtype.size);
  const size_t available = bytes.size() - h.data_offset;
  if (available != needed) {
    th::fail(name, ": ", available < needed ? "truncated: " : "", "shape ",
             detail::shape_repr(h.shape), " of ", h.dtype.name(), " needs ", needed,
             " bytes of data from byte ", h.data_offset, ", the file has ", available);
  }
  return detail::decode_array(bytes.substr(h.data_offset), h.dtype, h.shape, h.fortran);
}

// numpy's _write_array_header + _wrap_header for a C-order array.
std::string header_bytes(const std::string& descr, const std::vector<int64_t>& shape) {
  std::string dict = "{'descr': '" + descr +
                     "', 'fortran_order': False, 'shape': " + detail::shape_repr(shape) + ", }";
  if (!shape.empty())
    dict.append(
        kGrowthAxisDigits - std::min<size_t>(kGrowthAxisDigits, std::to_string(shape[0]).size()),
        ' ');
  const size_t hlen = dict.size() + 1;  // + '\n'
  size_t length_size = 2;
  size_t pad = kArrayAlign - ((kMagic.size() + 2 + length_size + hlen) % kArrayAlign);
  if (hlen + pad > 0xffff) {  // format 2.0, as numpy falls back to
    length_size = 4;
    pad = kArrayAlign - ((kMagic.size() + 2 + length_size + hlen) % kArrayAlign);
  }
  std::string out(kMagic);
  out.push_back(static_cast<char>(length_size == 2 ? 1 : 2));
  out.push_back('\0');
  detail::append_le(out, hlen + pad, static_cast<int>(length_size));
  out += dict;
  out.append(pad, ' ');
  out.push_back('\n');
  return out;
}

}  // namespace

torch::Tensor parse_npy(const std::string& bytes, const std::string& name) {
  const Header h = parse_header(bytes, name);
  if (h.dtype.is_object())
    th::fail(name, ": holds Python objects ('|O'); read it with read_npy_value");
  return numeric_data(bytes, h, name);
}

torch::Tensor read_npy(const std::filesystem::path& path) {
  return parse_npy(detail::read_file(path), path.string());
}

Value parse_npy_value(const std::string& bytes, const std::string& name) {
  const Header h = parse_header(bytes, name);
  if (!h.dtype.is_object()) return Value::array(numeric_data(bytes, h, name));
  // np.save pickled the whole object array; a 0-d one unpickles to the object it holds.
  return parse_pickle(std::string_view(bytes).substr(h.data_offset),
                      name + " (pickle at byte " + std::to_string(h.data_offset) + ")");
}

Value read_npy_value(const std::filesystem::path& path) {
  return parse_npy_value(detail::read_file(path), path.string());
}

std::string npy_bytes(const torch::Tensor& array) {
  const detail::NpyDType dtype = detail::dtype_of(array.scalar_type());
  return header_bytes(dtype.descr(), array.sizes().vec()) + detail::encode_array(array.cpu());
}

void write_npy(const std::filesystem::path& path, const torch::Tensor& array) {
  detail::write_file_atomic(path, npy_bytes(array));
}

std::string npy_value_bytes(const Value& object) {
  if (object.kind() == Value::Kind::Array) return npy_bytes(object.as_tensor());
  return header_bytes("|O", {}) + detail::pickle_object_array(object, 3);
}

void write_npy_value(const std::filesystem::path& path, const Value& object) {
  detail::write_file_atomic(path, npy_value_bytes(object));
}

std::map<std::string, torch::Tensor> parse_npz(const std::string& bytes, const std::string& name) {
  std::map<std::string, torch::Tensor> arrays;
  for (auto& member : read_zip(bytes, name)) {
    std::string key = member.name;
    if (key.size() >= 4 && key.compare(key.size() - 4, 4, ".npy") == 0) key.resize(key.size() - 4);
    arrays[key] = parse_npy(member.data, name + "/" + member.name);
  }
  return arrays;
}

std::map<std::string, torch::Tensor> read_npz(const std::filesystem::path& path) {
  return parse_npz(detail::read_file(path), path.string());
}

std::string npz_bytes(const std::map<std::string, torch::Tensor>& arrays) {
  std::vector<std::pair<std::string, std::string>> members;
  for (const auto& [key, array] : arrays) members.emplace_back(key + ".npy", npy_bytes(array));
  return write_zip(members);
}

void write_npz(const std::filesystem::path& path,
               const std::map<std::string, torch::Tensor>& arrays) {
  detail::write_file_atomic(path, npz_bytes(arrays));
}

}  // namespace th::io
