#include "io/bytes.hpp"

#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <sstream>

#include "core/error.hpp"
#include "core/files.hpp"

namespace th::io {

std::string read_file(const std::filesystem::path& path) {
  refuse_special_file(path, "input");
  std::ifstream in(path, std::ios::binary);
  if (!in) th::fail("cannot open '", path.string(), "': ", std::strerror(errno));
  std::ostringstream buffer;
  buffer << in.rdbuf();
  if (in.bad()) th::fail("cannot read '", path.string(), "'");
  return std::move(buffer).str();
}

void write_file_atomic(const std::filesystem::path& path, std::string_view bytes) {
  th::write_file_atomic(path, bytes);
}

}  // namespace th::io

namespace th::io::detail {

std::string shape_repr(const std::vector<int64_t>& shape) {
  std::string out = "(";
  for (size_t i = 0; i < shape.size(); ++i) {
    if (i > 0) out += ", ";
    out += std::to_string(shape[i]);
  }
  if (shape.size() == 1) out += ",";
  return out + ")";
}

namespace {

// Calls f(code point) for each code point; false when the text is not well-formed UTF-8.
template <class F>
bool for_each_code_point(std::string_view text, F&& f) {
  for (size_t i = 0; i < text.size();) {
    const auto b0 = static_cast<uint8_t>(text[i]);
    if (b0 < 0x80) {
      if (!f(uint32_t{b0})) return false;
      ++i;
      continue;
    }
    int extra = 0;
    uint32_t cp = 0, min = 0;
    if ((b0 & 0xe0) == 0xc0) {
      extra = 1, cp = b0 & 0x1f, min = 0x80;
    } else if ((b0 & 0xf0) == 0xe0) {
      extra = 2, cp = b0 & 0x0f, min = 0x800;
    } else if ((b0 & 0xf8) == 0xf0) {
      extra = 3, cp = b0 & 0x07, min = 0x10000;
    } else {
      return false;
    }
    if (i + extra >= text.size()) return false;
    for (int k = 1; k <= extra; ++k) {
      const auto b = static_cast<uint8_t>(text[i + k]);
      if ((b & 0xc0) != 0x80) return false;
      cp = (cp << 6) | (b & 0x3f);
    }
    if (cp < min || cp > 0x10ffff || !f(cp)) return false;
    i += 1 + extra;
  }
  return true;
}

}  // namespace

std::optional<size_t> utf8_length(std::string_view text) {
  size_t n = 0;
  if (!for_each_code_point(text, [&](uint32_t) { return ++n, true; })) return std::nullopt;
  return n;
}

std::optional<std::string> utf8_to_latin1(std::string_view text) {
  std::string out;
  out.reserve(text.size());
  const bool ok = for_each_code_point(text, [&](uint32_t cp) {
    out.push_back(static_cast<char>(cp));
    return cp < 256;
  });
  if (!ok) return std::nullopt;
  return out;
}

std::string latin1_to_utf8(std::string_view bytes) {
  std::string out;
  out.reserve(bytes.size() + bytes.size() / 4);
  for (char c : bytes) {
    const auto b = static_cast<uint8_t>(c);
    if (b < 0x80) {
      out.push_back(c);
    } else {
      out.push_back(static_cast<char>(0xc0 | (b >> 6)));
      out.push_back(static_cast<char>(0x80 | (b & 0x3f)));
    }
  }
  return out;
}

}  // namespace th::io::detail
