#pragma once
// Inputs that must be files: a FIFO, a device or a socket where a file is expected is refused by
// name before it is opened (reading one may block or never end).

#include <filesystem>
#include <string>
#include <string_view>

#include "core/error.hpp"

namespace th {

// What a path that is not a regular file is, in words ("FIFO (named pipe)", "folder", ...).
inline const char* file_kind(std::filesystem::file_type type) {
  using std::filesystem::file_type;
  switch (type) {
    case file_type::directory:
      return "folder";
    case file_type::fifo:
      return "FIFO (named pipe)";
    case file_type::character:
      return "character device";
    case file_type::block:
      return "block device";
    case file_type::socket:
      return "socket";
    default:
      return "special file";
  }
}

// Fails when `path` exists (following links) and is not a regular file: "<what> '<path>' is a
// <kind>, not a file". A missing path is left to the caller's own message.
inline void refuse_special_file(const std::filesystem::path& path, const std::string& what) {
  std::error_code ec;
  const auto type = std::filesystem::status(path, ec).type();
  if (ec || type == std::filesystem::file_type::not_found ||
      type == std::filesystem::file_type::regular)
    return;
  fail(what, " '", path.string(), "' is a ", file_kind(type), ", not a file");
}

// True when `path` exists (links followed), false when it does not; any other answer (a loop of
// symbolic links, a folder that may not be searched) fails: "cannot use '<path>': <reason>".
inline bool exists_or_fail(const std::filesystem::path& path) {
  std::error_code ec;
  const auto status = std::filesystem::status(path, ec);
  if (status.type() == std::filesystem::file_type::not_found) return false;
  if (ec) fail("cannot use '", path.string(), "': ", ec.message());
  return true;
}

// True when `inner` is `outer` or lies inside it, both resolved first (absolute and normal, links
// followed as far as the paths exist).
bool path_within(const std::filesystem::path& inner, const std::filesystem::path& outer);
// The same with the paths as given: absolute and normal, no link followed (a link inside a folder
// lies inside it, wherever it points).
bool path_within_as_given(const std::filesystem::path& inner, const std::filesystem::path& outer);

// Writes `bytes` to `path` through a new temporary file in the same folder (created exclusively,
// never through a link), renamed over `path`: readers never see a half-written file, and a link
// at `path` is replaced, not written through. Throws th::Error naming the path.
void write_file_atomic(const std::filesystem::path& path, std::string_view bytes);

// A new, empty file beside `path` for a writer that needs a file name (a video encoder): created
// exclusively (no link followed), named `<stem>.tmp<pid>.<n><extension>` so the extension still
// says the format. Commit it with std::filesystem::rename over `path`.
std::filesystem::path create_temporary_beside(const std::filesystem::path& path);

}  // namespace th
