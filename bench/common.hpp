#pragma once
// What the benchmarks share: number formatting, wall time and peak memory of a section.
// Memory: peak bytes of live LibTorch CPU tensors (c10's memory-reporting hook) and the resident
// set growth (Linux VmHWM after resetting it through /proc/self/clear_refs).

#include <c10/core/Allocator.h>
#include <c10/util/ThreadLocalDebugInfo.h>
#include <torch/torch.h>

#include <algorithm>
#include <chrono>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <iostream>
#include <memory>
#include <sstream>
#include <string>

#include "core/error.hpp"
#include "core/torch_compat.hpp"
#include "render/volume.hpp"

namespace th::bench {

using Clock = std::chrono::steady_clock;

inline std::string fmt(double v, int prec = 1) {
  std::ostringstream s;
  s << std::fixed << std::setprecision(prec) << v;
  return s.str();
}

// A profile's stages with their parts ("dparf.fields" inside "dparf") added into the stage:
// each stage's whole time and work, then (for the roofline) each part's own.
struct StageRow {
  std::string stage;
  double seconds = 0;
  render::Work work;
  bool part = false;
};
inline std::vector<StageRow> stage_rows(const render::Profile& p, bool with_parts) {
  std::vector<StageRow> rows;
  auto row = [&](const std::string& name, bool part) -> StageRow& {
    for (auto& r : rows)
      if (r.stage == name) return r;
    rows.push_back({name, 0, {}, part});
    return rows.back();
  };
  for (const auto& [stage, sec] : p.seconds) {
    const auto dot = stage.find('.');
    const auto it = p.work.find(stage);
    const render::Work w = it == p.work.end() ? render::Work{} : it->second;
    auto& top = row(stage.substr(0, dot), false);
    top.seconds += sec;
    top.work.flops += w.flops;
    top.work.bytes += w.bytes;
    if (dot != std::string::npos && with_parts) {
      auto& part = row(stage, true);
      part.seconds += sec;
      part.work = w;
    }
  }
  // Stages in name order, each followed by its parts ("dparf" < "dparf.codes" < "fdi").
  std::sort(rows.begin(), rows.end(), [](auto& a, auto& b) { return a.stage < b.stage; });
  return rows;
}

// "dparf 1.04 (fields 0.29, codes 0.28), fdi 2.70": each stage's time, its parts' in brackets.
inline std::string stage_seconds(const render::Profile& p) {
  std::string out;
  bool open = false;
  for (const auto& row : stage_rows(p, true)) {
    if (row.part) {
      out += (open ? ", " : " (") + row.stage.substr(row.stage.find('.') + 1) + " " +
             fmt(row.seconds, 2);
      open = true;
      continue;
    }
    if (open) out += ")";
    open = false;
    out += (out.empty() ? "" : ", ") + row.stage + " " + fmt(row.seconds, 2);
  }
  return open ? out + ")" : out;
}

inline double seconds_since(Clock::time_point t) {
  return std::chrono::duration<double>(Clock::now() - t).count();
}

inline int64_t status_kb(const char* key) {
  std::ifstream f("/proc/self/status");
  std::string line;
  while (std::getline(f, line))
    if (line.rfind(key, 0) == 0) return std::stoll(line.substr(std::strlen(key)));
  return -1;
}

// Peak bytes of LibTorch CPU tensors allocated during a section and still alive, from c10's
// memory-reporting hook (the allocator reports every allocation and free to the thread's
// MemoryReportingInfoBase while one is installed).
struct TensorMemoryHook : c10::MemoryReportingInfoBase {
  int64_t base = -1, peak = 0;
  void reportMemoryUsage(void*, int64_t size, th::compat::MemoryTotal total,
                         th::compat::MemoryTotal, c10::Device device) override {
    if (!device.is_cpu()) return;
    const auto total_allocated = static_cast<int64_t>(total);
    if (base < 0) base = total_allocated - size;
    peak = std::max(peak, total_allocated - base);
  }
  bool memoryProfilingEnabled() const override { return true; }
};

// Peak memory of a section: tensor bytes (allocator hook) and the resident-set growth (VmHWM
// after a reset through /proc/self/clear_refs, minus VmRSS before; a lower bound when freed
// heap memory is reused).
struct PeakMemory {
  int64_t base_kb;
  std::shared_ptr<TensorMemoryHook> hook = std::make_shared<TensorMemoryHook>();
  c10::DebugInfoGuard guard{c10::DebugInfoKind::PROFILER_STATE, hook};
  PeakMemory() {
    std::ofstream("/proc/self/clear_refs") << "5";
    base_kb = status_kb("VmRSS:");
  }
  double tensor_mib() const { return hook->peak / 1048576.0; }
  double rss_mib() const { return (status_kb("VmHWM:") - base_kb) / 1024.0; }
  std::string text() const {
    return fmt(tensor_mib(), 0) + " MiB tensors (RSS +" + fmt(rss_mib(), 0) + " MiB)";
  }
};

// A benchmark that writes its figures over `out` (not appending) refuses an existing file unless
// `force`: the results kept in bench/results/ are replaced only on purpose. Checked before
// anything is measured. Throws th::Error.
inline void refuse_overwriting(const std::filesystem::path& out, bool force) {
  std::error_code ec;
  if (out.empty() || force || !std::filesystem::exists(std::filesystem::symlink_status(out, ec)))
    return;
  th::fail("--out '", out.string(), "' exists: --force to replace it, or --out another file");
}

// Lines printed and kept for the markdown file.
struct Report {
  std::ostringstream md;
  void line(const std::string& s) {
    std::cout << s << std::endl;
    md << s << "\n";
  }
};

// "1.23 0.98 0.75": the machine's 1, 5 and 15 minute load averages.
inline std::string load_average() {
  std::ifstream f("/proc/loadavg");
  std::string a, b, c;
  f >> a >> b >> c;
  return a + " " + b + " " + c;
}

// The commit of the working tree (git rev-parse --short HEAD, "+" when it has changes),
// "unknown" outside a git checkout.
inline std::string git_commit() {
  std::string out;
  if (FILE* f = popen("git rev-parse --short HEAD 2>/dev/null && git status --porcelain -uno "
                      "2>/dev/null | head -1",
                      "r")) {
    char buf[256];
    while (fgets(buf, sizeof buf, f)) out += buf;
    pclose(f);
  }
  const auto nl = out.find('\n');
  if (nl == std::string::npos) return "unknown";
  return out.substr(0, nl) + (out.size() > nl + 1 ? "+" : "");
}

// The processor's model name (/proc/cpuinfo), "unknown" when it has none.
inline std::string cpu_model() {
  std::ifstream f("/proc/cpuinfo");
  std::string line;
  while (std::getline(f, line))
    if (line.rfind("model name", 0) == 0 && line.find(':') != std::string::npos) {
      auto v = line.substr(line.find(':') + 1);
      return v.substr(v.find_first_not_of(' '));
    }
  return "unknown";
}

}  // namespace th::bench
