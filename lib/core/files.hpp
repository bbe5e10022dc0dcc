#pragma once
// Inputs that must be files: a FIFO, a device or a socket where a file is expected is refused by
// name before it is opened (reading one may block or never end).

#include <filesystem>
#include <string>

#include "core/error.hpp"

namespace th {

// What a path that is not a regular file is, in words ("FIFO (named pipe)", "folder", ...).
inline const char* file_kind(std::filesystem::file_type type) {
  using std::filesystem::file_type;
  switch (type) {
    case file_type::directory: return "folder";
    case file_type::fifo: return "FIFO (named pipe)";
    case file_type::character: return "character device";
    case file_type::block: return "block device";
    case file_type::socket: return "socket";
    default: return "special file";
  }
}

// Fails when `path` exists (following links) and is not a regular file: "<what> '<path>' is a
// <kind>, not a file". A missing path is left to the caller's own message.
inline void refuse_special_file(const std::filesystem::path& path, const std::string& what) {
  std::error_code ec;
  const auto type = std::filesystem::status(path, ec).type();
  if (ec || type == std::filesystem::file_type::not_found || type == std::filesystem::file_type::regular) return;
  fail(what, " '", path.string(), "' is a ", file_kind(type), ", not a file");
}

// True when `inner` is `outer` or lies inside it, both resolved first (absolute and normal, links
// followed as far as the paths exist).
inline bool path_within(const std::filesystem::path& inner, const std::filesystem::path& outer) {
  auto resolved = [](const std::filesystem::path& p) {
    std::error_code ec;
    const auto c = std::filesystem::weakly_canonical(std::filesystem::absolute(p), ec);
    return ec ? std::filesystem::absolute(p).lexically_normal() : c;
  };
  const auto in = resolved(inner), out = resolved(outer);
  auto i = in.begin();
  for (const auto& part : out) {
    if (part.empty()) continue;  // a trailing separator
    if (i == in.end() || *i != part) return false;
    ++i;
  }
  return true;
}

}  // namespace th
