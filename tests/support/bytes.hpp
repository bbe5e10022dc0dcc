#pragma once
// Byte-for-byte comparison of binary files for CHECKs: on a mismatch the message names the
// sizes, the first differing offset and a short escaped excerpt of both sides, instead of
// printing whole binary strings (which Catch2 3 cannot lay out: it aborts on them).

#include <algorithm>
#include <cstdio>
#include <string>

namespace th::test {

namespace detail {
inline std::string escaped(const std::string& s, size_t from, size_t count) {
  std::string out;
  for (size_t i = from; i < std::min(s.size(), from + count); ++i) {
    const unsigned char c = static_cast<unsigned char>(s[i]);
    if (c >= 0x20 && c < 0x7f && c != '\\') {
      out += static_cast<char>(c);
    } else {
      char hex[5];
      std::snprintf(hex, sizeof hex, "\\x%02x", c);
      out += hex;
    }
  }
  return out;
}
}  // namespace detail

// "" when `got` and `want` are the same bytes; otherwise where and how they differ.
inline std::string byte_difference(const std::string& got, const std::string& want) {
  if (got == want) return "";
  const auto at = static_cast<size_t>(
      std::mismatch(got.begin(), got.begin() + std::min(got.size(), want.size()), want.begin())
          .first -
      got.begin());
  const size_t from = at >= 16 ? at - 16 : 0;
  return std::to_string(got.size()) + " bytes vs " + std::to_string(want.size()) +
         ", first difference at byte " + std::to_string(at) + ": got \"" +
         detail::escaped(got, from, 48) + "\", want \"" + detail::escaped(want, from, 48) + "\"";
}

}  // namespace th::test
