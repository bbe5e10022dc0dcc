#include "pipeline/jsonl.hpp"

#include <cmath>
#include <cstdio>
#include <cstdlib>

#include "core/error.hpp"

namespace th::pipeline {
namespace {

std::string dump(const nlohmann::ordered_json& value) {
  return value.dump(-1, ' ', false, nlohmann::ordered_json::error_handler_t::replace);
}

}  // namespace

JsonLine& JsonLine::add(const std::string& key, double value) {
  if (!std::isfinite(value)) {
    fields_[key] = nullptr;
    return *this;
  }
  // Rounded to 9 significant digits: nlohmann then writes the shortest form of that.
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.9g", value);
  fields_[key] = std::strtod(buf, nullptr);
  return *this;
}

JsonLine& JsonLine::add(const std::string& key, int64_t value) {
  fields_[key] = value;
  return *this;
}

JsonLine& JsonLine::add(const std::string& key, const std::string& value) {
  fields_[key] = value;
  return *this;
}

std::string JsonLine::dump_line(const nlohmann::ordered_json& value) {
  if (!value.is_object()) return dump(value);
  std::string out = "{";
  for (const auto& field : value.items())
    out += (out.size() > 1 ? ", " : "") + dump(field.key()) + ": " + dump(field.value());
  return out + "}";
}

JsonlWriter::JsonlWriter(const std::filesystem::path& file)
    : file_(file), out_(file, std::ios::app) {
  if (!out_) fail("cannot open '", file.string(), "' for writing");
}

void JsonlWriter::write(const JsonLine& line) {
  out_ << line.str() << '\n';
  out_.flush();
  if (!out_) fail("cannot write to '", file_.string(), "'");
}

}  // namespace th::pipeline
