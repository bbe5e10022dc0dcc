#pragma once
// Metrics as JSON lines: one object per line, appended and flushed, so a crashed run keeps every
// line it wrote and tools can tail the file.

#include <filesystem>
#include <fstream>
#include <string>
#include <utility>
#include <vector>

namespace th::pipeline {

class JsonLine {
 public:
  JsonLine& add(const std::string& key, double value);
  JsonLine& add(const std::string& key, int64_t value);
  JsonLine& add(const std::string& key, int value) { return add(key, int64_t(value)); }
  JsonLine& add(const std::string& key, const std::string& value);
  std::string str() const;

 private:
  std::vector<std::pair<std::string, std::string>> fields_;  // key, JSON-encoded value
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
