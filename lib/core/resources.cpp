#include "core/resources.hpp"

#include <spdlog/spdlog.h>
#include <unistd.h>

#include <cmath>

#include "core/error.hpp"

namespace th::resources {

int64_t physical_memory_bytes() {
  const long pages = sysconf(_SC_PHYS_PAGES), page = sysconf(_SC_PAGESIZE);
  return pages > 0 && page > 0 ? int64_t(pages) * page : 0;
}

double memory_limit_bytes(double max_memory_gb) {
  if (max_memory_gb > 0) return max_memory_gb * double(1 << 30);
  const int64_t physical = physical_memory_bytes();
  return physical > 0 ? 0.75 * double(physical) : 16.0 * double(1 << 30);
}

std::string bytes_text(double bytes) {
  const double mib = bytes / double(1 << 20);
  return mib >= 1024 ? fmt::format("{:.1f} GiB", mib / 1024) : fmt::format("{:.0f} MiB", mib);
}

void check(const Estimate& e, double max_memory_gb) {
  if (!(max_memory_gb >= 0) || !std::isfinite(max_memory_gb))
    fail("max_memory_gb must be >= 0 (0: 3/4 of physical memory), got ", max_memory_gb);
  std::string time;
  if (e.samples > 0 && e.threads > 0) {
    const double seconds = e.samples / (kSamplesPerSecondPerThread * e.threads);
    time = seconds < 120    ? fmt::format(", about {:.0f} s", seconds)
           : seconds < 7200 ? fmt::format(", about {:.0f} min", seconds / 60)
                            : fmt::format(", about {:.1f} h", seconds / 3600);
    time += fmt::format(" on {} CPU thread{}", e.threads, e.threads == 1 ? "" : "s");
  }
  const std::string samples =
      e.samples > 0 ? fmt::format(", up to {:.3g} network samples", e.samples) : "";
  const double limit = memory_limit_bytes(max_memory_gb);
  spdlog::info("{}: estimated peak memory {}{}{}", e.what, bytes_text(e.bytes), samples, time);
  if (e.bytes > limit)
    fail(e.what, ": estimated peak memory ", bytes_text(e.bytes), " is above the limit of ",
         bytes_text(limit),
         max_memory_gb > 0 ? " (max_memory_gb=" + fmt::format("{}", max_memory_gb) + ")"
                           : std::string(" (3/4 of this machine's memory)"),
         "; ask for less, or raise the limit with max_memory_gb=<GiB>");
}

}  // namespace th::resources
