#pragma once
// Metrics as JSON lines: one object per line, appended and flushed, so a crashed run keeps every
// line it wrote and tools can tail the file.

#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <string>

namespace th::pipeline {

// One record, its keys in the order they were added. Numbers keep 9 significant digits (what
// a float holds; the files stay short); NaN and infinities are written as null (JSON has no
// such numbers).
class JsonLine {
 public:
  JsonLine& add(const std::string& key, double value);
  JsonLine& add(const std::string& key, int64_t value);
  JsonLine& add(const std::string& key, int value) { return add(key, int64_t(value)); }
  JsonLine& add(const std::string& key, const std::string& value);
  const nlohmann::ordered_json& json() const { return fields_; }
  std::string str() const { return dump_line(fields_); }

  // `value` on one line as metrics.jsonl and summary.json are written: `{"key": value, ...}`,
  // a space after each ':' and ',' of the outer object (tools grep for `"step": 12`). Bytes that
  // are not UTF-8 in a string become U+FFFD.
  static std::string dump_line(const nlohmann::ordered_json& value);

 private:
  nlohmann::ordered_json fields_ = nlohmann::ordered_json::object();
};

class JsonlWriter {
 public:
  explicit JsonlWriter(const std::filesystem::path& file);  // appends
  void write(const JsonLine& line);

 private:
  std::filesystem::path file_;
  std::ofstream out_;
};

}  // namespace th::pipeline
