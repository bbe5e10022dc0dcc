#pragma once
// Small byte-level helpers shared by the .npy, .npz and pickle code (internal to lib/io).

#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "io/files.hpp"

namespace th::io::detail {

static_assert(__BYTE_ORDER__ == __ORDER_LITTLE_ENDIAN__, "lib/io assumes a little-endian host");

using io::read_file;
using io::write_file_atomic;

// Little-endian integers (the caller checks bounds).
inline uint64_t load_le(const char* p, int n) {
  uint64_t v = 0;
  for (int i = n - 1; i >= 0; --i) v = (v << 8) | static_cast<uint8_t>(p[i]);
  return v;
}
inline void append_le(std::string& out, uint64_t v, int n) {
  for (int i = 0; i < n; ++i) out.push_back(static_cast<char>((v >> (8 * i)) & 0xff));
}

// Python's repr of a tuple of ints: "()", "(3,)", "(2, 3)".
std::string shape_repr(const std::vector<int64_t>& shape);

// Number of code points of UTF-8 text; nullopt when malformed (lone surrogates are accepted,
// as Python's "surrogatepass" does).
std::optional<size_t> utf8_length(std::string_view text);
// Latin-1 bytes of UTF-8 text whose code points are all below 256 (Python's
// s.encode('latin1')); nullopt otherwise.
std::optional<std::string> utf8_to_latin1(std::string_view text);
// UTF-8 of latin-1 bytes (Python's b.decode('latin1')).
std::string latin1_to_utf8(std::string_view bytes);

}  // namespace th::io::detail
