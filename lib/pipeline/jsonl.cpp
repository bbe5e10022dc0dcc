#include "pipeline/jsonl.hpp"

#include <cmath>
#include <cstdio>

#include "core/error.hpp"

namespace th::pipeline {
namespace {

std::string quote(const std::string& s) {
  std::string out = "\"";
  for (char c : s) {
    switch (c) {
      case '"': out += "\\\""; break;
      case '\\': out += "\\\\"; break;
      case '\n': out += "\\n"; break;
      case '\t': out += "\\t"; break;
      default:
        if (static_cast<unsigned char>(c) < 0x20) {
          char buf[8];
          std::snprintf(buf, sizeof buf, "\\u%04x", c);
          out += buf;
        } else {
          out += c;
        }
    }
  }
  return out + "\"";
}

}  // namespace

JsonLine& JsonLine::add(const std::string& key, double value) {
  char buf[32];
  if (std::isfinite(value)) std::snprintf(buf, sizeof buf, "%.9g", value);
  else std::snprintf(buf, sizeof buf, "null");  // JSON has no NaN/inf
  fields_.emplace_back(key, buf);
  return *this;
}

JsonLine& JsonLine::add(const std::string& key, int64_t value) {
  fields_.emplace_back(key, std::to_string(value));
  return *this;
}

JsonLine& JsonLine::add(const std::string& key, const std::string& value) {
  fields_.emplace_back(key, quote(value));
  return *this;
}

std::string JsonLine::str() const {
  std::string out = "{";
  for (size_t i = 0; i < fields_.size(); ++i)
    out += (i ? ", " : "") + quote(fields_[i].first) + ": " + fields_[i].second;
  return out + "}";
}

JsonlWriter::JsonlWriter(const std::filesystem::path& file) : file_(file), out_(file, std::ios::app) {
  if (!out_) fail("cannot open '", file.string(), "' for writing");
}

void JsonlWriter::write(const JsonLine& line) {
  out_ << line.str() << '\n';
  out_.flush();
  if (!out_) fail("cannot write to '", file_.string(), "'");
}

}  // namespace th::pipeline
