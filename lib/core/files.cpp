#include "core/files.hpp"

#include <fcntl.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <cstring>

namespace th {
namespace fs = std::filesystem;

namespace {

bool has_prefix(const fs::path& in, const fs::path& out) {
  auto i = in.begin();
  for (const auto& part : out) {
    if (part.empty()) continue;  // a trailing separator
    if (i == in.end() || *i != part) return false;
    ++i;
  }
  return true;
}

fs::path as_given(const fs::path& p) { return fs::absolute(p).lexically_normal(); }

fs::path resolved(const fs::path& p) {
  std::error_code ec;
  const auto c = fs::weakly_canonical(fs::absolute(p), ec);
  return ec ? as_given(p) : c;
}

// Opens a new file exclusively (O_EXCL | O_NOFOLLOW): never an existing file, never a link.
int create_exclusive(const fs::path& path, const fs::path& target) {
  const int fd = ::open(path.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_NOFOLLOW | O_CLOEXEC, 0644);
  if (fd < 0) fail("cannot write '", target.string(), "': ", std::strerror(errno));
  return fd;
}

fs::path temporary_name(const fs::path& path, bool keep_extension) {
  static std::atomic<uint64_t> counter{0};
  const std::string tag = ".tmp" + std::to_string(::getpid()) + "." + std::to_string(counter++);
  if (!keep_extension) return fs::path(path.string() + tag);
  fs::path tmp = path.parent_path() / path.stem();
  tmp += tag + path.extension().string();
  return tmp;
}

}  // namespace

bool path_within(const fs::path& inner, const fs::path& outer) {
  return has_prefix(resolved(inner), resolved(outer));
}

bool path_within_as_given(const fs::path& inner, const fs::path& outer) {
  return has_prefix(as_given(inner), as_given(outer));
}

void write_file_atomic(const fs::path& path, std::string_view bytes) {
  const fs::path tmp = temporary_name(path, false);
  const int fd = create_exclusive(tmp, path);
  auto discard = [&] {
    std::error_code ignored;
    fs::remove(tmp, ignored);
  };
  size_t done = 0;
  while (done < bytes.size()) {
    const ssize_t n = ::write(fd, bytes.data() + done, bytes.size() - done);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) {
      const int err = errno;
      ::close(fd);
      discard();
      fail("cannot write '", path.string(), "': ", std::strerror(err),
           err == ENOSPC || err == EDQUOT ? " (disk full?)" : "");
    }
    done += size_t(n);
  }
  if (::close(fd) != 0) {
    const int err = errno;
    discard();
    fail("cannot write '", path.string(), "': ", std::strerror(err),
         err == ENOSPC || err == EDQUOT ? " (disk full?)" : "");
  }
  std::error_code ec;
  fs::rename(tmp, path, ec);
  if (ec) {
    discard();
    fail("cannot write '", path.string(), "': ", ec.message());
  }
}

fs::path create_temporary_beside(const fs::path& path) {
  const fs::path tmp = temporary_name(path, true);
  ::close(create_exclusive(tmp, path));
  return tmp;
}

}  // namespace th
