#pragma once
// A progress reporter for long loops: a live bar with rate and ETA on a terminal, plain
// periodic log lines otherwise (so CI logs stay readable).

#include <chrono>
#include <cstdint>
#include <string>

namespace th {

class Progress {
 public:
  // total: number of steps (0 if unknown); unit: what a step is ("img", "step", "frame").
  Progress(std::string label, int64_t total, std::string unit = "it");
  ~Progress();
  Progress(const Progress&) = delete;
  Progress& operator=(const Progress&) = delete;

  // Advances by n steps; `note` is shown after the bar (e.g. "loss 0.012").
  void advance(int64_t n = 1, const std::string& note = "");
  void finish();

  // Forces the mode (tests): true = terminal bar, false = periodic lines.
  void set_interactive(bool interactive) { interactive_ = interactive; }
  // Formats seconds as 1h02m, 3m05s or 4.2s.
  static std::string format_duration(double seconds);
  // The line that would be printed now (for tests and for the log file).
  std::string status_line(const std::string& note) const;

 private:
  using Clock = std::chrono::steady_clock;
  void print(const std::string& note, bool final);

  std::string label_;
  std::string unit_;
  int64_t total_;
  int64_t done_ = 0;
  bool interactive_;
  bool finished_ = false;
  Clock::time_point start_;
  Clock::time_point last_print_;
  double line_interval_s_ = 10.0;  // plain mode: at most one line per interval
};

}  // namespace th
