#include "core/progress.hpp"

#include <spdlog/spdlog.h>
#include <unistd.h>

#include <cmath>
#include <cstdio>

namespace th {

Progress::Progress(std::string label, int64_t total, std::string unit)
    : label_(std::move(label)),
      unit_(std::move(unit)),
      total_(total),
      interactive_(isatty(fileno(stderr)) != 0),
      start_(Clock::now()),
      last_print_(start_) {}

Progress::~Progress() {
  if (!finished_) finish();
}

std::string Progress::format_duration(double s) {
  char buf[32];
  if (!std::isfinite(s) || s < 0) return "?";
  if (s < 60) {
    std::snprintf(buf, sizeof buf, "%.1fs", s);
  } else if (s < 3600) {
    std::snprintf(buf, sizeof buf, "%dm%02ds", int(s) / 60, int(s) % 60);
  } else {
    std::snprintf(buf, sizeof buf, "%dh%02dm", int(s) / 3600, (int(s) % 3600) / 60);
  }
  return buf;
}

std::string Progress::status_line(const std::string& note) const {
  const double elapsed = std::chrono::duration<double>(Clock::now() - start_).count();
  const double rate = elapsed > 0 ? done_ / elapsed : 0.0;
  char rate_buf[48];
  std::snprintf(rate_buf, sizeof rate_buf, "%.2f %s/s", rate, unit_.c_str());
  std::string line = label_ + " ";
  if (total_ > 0) {
    const double frac = std::min(1.0, double(done_) / double(total_));
    const int width = 24;
    const int filled = int(std::round(frac * width));
    line += "[" + std::string(filled, '#') + std::string(width - filled, '.') + "] ";
    line += std::to_string(done_) + "/" + std::to_string(total_) + " ";
    char pct[16];
    std::snprintf(pct, sizeof pct, "%3.0f%% ", frac * 100);
    line += pct;
    const double eta = rate > 0 ? (total_ - done_) / rate : NAN;
    line += std::string(rate_buf) + " elapsed " + format_duration(elapsed) + " ETA " +
            format_duration(eta);
  } else {
    line += std::to_string(done_) + " " + unit_ + " " + rate_buf + " elapsed " +
            format_duration(elapsed);
  }
  if (!note.empty()) line += "  " + note;
  return line;
}

void Progress::print(const std::string& note, bool final) {
  const std::string line = status_line(note);
  if (interactive_) {
    std::fprintf(stderr, "\r\033[2K%s%s", line.c_str(), final ? "\n" : "");
    std::fflush(stderr);
  } else {
    spdlog::info("{}", line);
  }
}

void Progress::advance(int64_t n, const std::string& note) {
  done_ += n;
  const auto now = Clock::now();
  const double since = std::chrono::duration<double>(now - last_print_).count();
  const double interval = interactive_ ? 0.2 : line_interval_s_;
  const bool first = done_ == n;
  if (since >= interval || first || (total_ > 0 && done_ >= total_)) {
    last_print_ = now;
    print(note, false);
  }
}

void Progress::finish() {
  if (finished_) return;
  finished_ = true;
  print("done", true);
}

}  // namespace th
