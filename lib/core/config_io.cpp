#include "core/config_io.hpp"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <cctype>
#include <charconv>
#include <cmath>
#include <fstream>
#include <limits>
#include <set>
#include <sstream>

#include "core/files.hpp"

namespace th::config {
namespace fs = std::filesystem;

namespace {

// Recursively merges `over` into `base` (maps merge key by key; anything else replaces).
void merge_into(YAML::Node base, const YAML::Node& over) {
  for (const auto& kv : over) {
    const std::string key = kv.first.as<std::string>();
    YAML::Node existing = base[key];
    if (existing.IsDefined() && existing.IsMap() && kv.second.IsMap()) {
      merge_into(existing, kv.second);
    } else {
      base[key] = YAML::Clone(kv.second);
    }
  }
}

// More nodes than any config has, and few enough to walk in well under a second.
constexpr size_t kMaxNodes = size_t{1} << 18;

// Aliases make the YAML tree a graph: `a: &x {b: *x}` is a cycle, and a chain of maps that each
// alias the one before twice doubles with every line (30 lines: 2^30 nodes). Everything after
// this check (merging, cloning, the typed reader) walks the tree, so refuse cycles, count the
// nodes the aliases expand to, and make sure every map key is a plain name.
void check_graph(const YAML::Node& node, const std::string& path, const std::string& source,
                 std::vector<YAML::Node>& ancestors, size_t& nodes) {
  if (++nodes > kMaxNodes)
    fail(source, ": more than ", kMaxNodes, " values (aliases repeat too much)");
  if (!node.IsMap() && !node.IsSequence()) return;
  for (const YAML::Node& a : ancestors)
    if (a.is(node)) fail(source, ": '", path, "' contains itself (an alias cycle)");
  ancestors.push_back(node);
  size_t index = 0;
  for (const auto& item : node) {
    if (node.IsSequence()) {
      check_graph(item, path + "[" + std::to_string(index++) + "]", source, ancestors, nodes);
      continue;
    }
    if (!item.first.IsScalar())
      fail(source, ": a key ", path.empty() ? "" : "under '" + path + "' ", "is not a plain name");
    const std::string key = item.first.Scalar();
    check_graph(item.second, path.empty() ? key : path + "." + key, source, ancestors, nodes);
  }
  ancestors.pop_back();
}

void check_graph(const YAML::Node& node, const std::string& source) {
  std::vector<YAML::Node> ancestors;
  size_t nodes = 0;
  check_graph(node, "", source, ancestors, nodes);
}

// Every key of a config file has a value and appears once per section (yaml-cpp would give a
// key without value as null, which reads as "use the default", and keep duplicate keys).
void check_values(const YAML::Node& node, const std::string& path, const fs::path& file) {
  std::set<std::string> keys;
  for (const auto& kv : node) {
    const std::string key = kv.first.Scalar();
    const std::string full = path.empty() ? key : path + "." + key;
    if (!keys.insert(key).second)
      fail("config file '", file.string(), "': key '", full, "' appears twice");
    if (kv.second.IsNull() && full != "parent")
      fail("config file '", file.string(), "': key '", full, "' has no value");
    if (kv.second.IsMap()) check_values(kv.second, full, file);
  }
}

// Bounds on what a config may be, checked before it is parsed.
constexpr size_t kMaxParents = 32;
constexpr uintmax_t kMaxConfigBytes = uintmax_t{1} << 20;

YAML::Node load_file_chain(const fs::path& file, std::vector<fs::path>& chain,
                           std::vector<fs::path>& named) {
  std::error_code ec;
  const fs::path canonical = fs::weakly_canonical(file, ec);
  refuse_special_file(file, "config file");
  if (!fs::is_regular_file(file)) fail("config file '", file.string(), "' does not exist");
  if (std::find(chain.begin(), chain.end(), canonical) != chain.end())
    fail("config file '", file.string(), "' is its own parent (inheritance cycle)");
  if (chain.size() >= kMaxParents)
    fail("config file '", file.string(), "': more than ", kMaxParents, " parent configs above it");
  chain.push_back(canonical);
  named.push_back(file);
  if (const auto bytes = fs::file_size(file, ec); !ec && bytes > kMaxConfigBytes)
    fail("config file '", file.string(), "' is ", bytes, " bytes, more than a config may be (",
         kMaxConfigBytes, ")");

  YAML::Node node;
  try {
    node = YAML::LoadFile(file.string());
  } catch (const YAML::Exception& e) {
    fail("config file '", file.string(), "': YAML error at line ", e.mark.line + 1, ", column ",
         e.mark.column + 1, ": ", e.msg);
  }
  if (node.IsNull())
    fail("config file '", file.string(),
         "' is empty (a config names at least its parent: 'parent: default.yaml')");
  if (!node.IsMap()) fail("config file '", file.string(), "' must hold a map of keys");
  check_graph(node, "config file '" + file.string() + "'");
  check_values(node, "", file);

  const YAML::Node parent = node["parent"];
  if (!parent.IsDefined() || parent.IsNull()) return node;
  if (!parent.IsScalar()) fail("config file '", file.string(), "': 'parent' must be a file name");
  const fs::path parent_file = file.parent_path() / parent.as<std::string>();
  YAML::Node merged = load_file_chain(parent_file, chain, named);
  node.remove("parent");
  merge_into(merged, node);
  return merged;
}

size_t edit_distance(const std::string& a, const std::string& b) {
  std::vector<size_t> row(b.size() + 1);
  for (size_t j = 0; j <= b.size(); ++j) row[j] = j;
  for (size_t i = 1; i <= a.size(); ++i) {
    size_t diag = row[0];
    row[0] = i;
    for (size_t j = 1; j <= b.size(); ++j) {
      const size_t up = row[j];
      row[j] = std::min({row[j] + 1, row[j - 1] + 1, diag + (a[i - 1] != b[j - 1])});
      diag = up;
    }
  }
  return row[b.size()];
}

}  // namespace

YAML::Node load_tree(const fs::path& file, const std::vector<std::string>& overrides,
                     std::vector<fs::path>* files_read) {
  std::vector<fs::path> chain, named;
  YAML::Node tree = load_file_chain(file, chain, named);
  if (files_read) files_read->insert(files_read->end(), named.begin(), named.end());
  for (const auto& o : overrides) apply_override(tree, o);
  return tree;
}

void apply_override(YAML::Node& root, const std::string& text) {
  const auto eq = text.find('=');
  if (eq == std::string::npos || eq == 0)
    fail("override '", text, "' must look like key.sub.key=value");
  const std::string path = text.substr(0, eq);
  const std::string raw = text.substr(eq + 1);

  std::vector<std::string> keys;
  std::stringstream ss(path);
  for (std::string k; std::getline(ss, k, '.');) {
    if (k.empty()) fail("override '", text, "': empty key in '", path, "'");
    keys.push_back(k);
  }
  YAML::Node value;
  try {
    value = raw.empty() ? YAML::Node(std::string()) : YAML::Load(raw);
  } catch (const YAML::Exception& e) {
    fail("override '", text, "': cannot parse value '", raw, "': ", e.msg);
  }
  check_graph(value, "override '" + text + "'");

  // Walk down with fresh handles (yaml-cpp nodes are references; reassigning would alias).
  std::vector<YAML::Node> nodes{root};
  for (size_t i = 0; i + 1 < keys.size(); ++i) {
    YAML::Node child = nodes.back()[keys[i]];
    if (!child.IsDefined() || child.IsNull()) {
      nodes.back()[keys[i]] = YAML::Node(YAML::NodeType::Map);
      child = nodes.back()[keys[i]];
    } else if (!child.IsMap()) {
      fail("override '", text, "': '", keys[i], "' is a value, not a section");
    }
    nodes.push_back(child);
  }
  nodes.back()[keys.back()] = value;
}

void Reader::retired(const char* key, const char* why) {
  seen_.insert(key);
  const YAML::Node child = node_[key];
  if (child.IsDefined())
    spdlog::warn("config key '{}' is no longer read and is ignored: {}",
                 detail::join_path(path_, key), why);
}

void Reader::check_unknown() const {
  if (!node_.IsMap()) return;
  for (const auto& kv : node_) {
    const std::string key = kv.first.as<std::string>();
    if (seen_.count(key)) continue;
    std::string best;
    size_t best_d = 3;  // suggest only close matches
    for (const auto& known : seen_) {
      const size_t d = edit_distance(key, known);
      if (d < best_d) best_d = d, best = known;
    }
    std::string known_list;
    for (const auto& known : seen_) known_list += (known_list.empty() ? "" : ", ") + known;
    if (!best.empty())
      fail("unknown config key '", detail::join_path(path_, key), "' (did you mean '",
           detail::join_path(path_, best), "'?)");
    fail("unknown config key '", detail::join_path(path_, key), "' (known here: ", known_list, ")");
  }
}

namespace {

// A bound as written in a message: integers without a decimal point, others as %g would.
std::string bound(double x) {
  std::ostringstream out;
  out << x;
  return out.str();
}

}  // namespace

std::string Range::text() const {
  const bool from = low != -std::numeric_limits<double>::infinity();
  const bool to = high != std::numeric_limits<double>::infinity();
  if (from && to)
    return "in " + std::string(low_open ? "(" : "[") + bound(low) + ", " + bound(high) +
           (high_open ? ")" : "]");
  if (from) return (low_open ? "> " : ">= ") + bound(low);
  if (to) return (high_open ? "< " : "<= ") + bound(high);
  return "";
}

void Reader::check_range(const std::string& path, double value, const Range& range,
                         const char* doc) {
  const std::string what = doc && *doc ? std::string(" (") + doc + ")" : "";
  if (!std::isfinite(value)) fail("config key '", path, "' = ", value, ": must be finite", what);
  if (!range.holds(value))
    fail("config key '", path, "' = ", bound(value), ": must be ", range.text(), what);
}

void Lister::add(const std::string& path, const std::string& type, const YAML::Node& value,
                 const Range& range, const char* doc) {
  YAML::Emitter out;
  out << YAML::Flow << value;
  out_.push_back({path, type, out.c_str(), range.text(), doc ? doc : "", range});
}

std::string describe(const std::vector<KeyInfo>& keys) {
  size_t width = 0;
  for (const auto& k : keys) width = std::max(width, k.key.size());
  std::ostringstream out;
  for (const auto& k : keys) {
    out << k.key << std::string(width + 2 - k.key.size(), ' ') << k.value << "  (" << k.type;
    if (!k.accepts.empty()) out << ", " << k.accepts;
    out << ")";
    if (!k.doc.empty()) out << "  " << k.doc;
    out << "\n";
  }
  return out.str();
}

void write_yaml(const fs::path& file, const YAML::Node& tree) {
  YAML::Emitter out;
  out << tree;
  write_file_atomic(
      file, std::string("# Resolved configuration: every option with the value this run used.\n") +
                out.c_str() + "\n");
}

std::optional<int64_t> decimal_integer(const std::string& text) {
  const char* begin = text.data();
  const char* end = begin + text.size();
  const bool plus = begin != end && *begin == '+';  // from_chars takes '-' only
  if (plus) ++begin;
  if (begin == end ||
      !(std::isdigit(static_cast<unsigned char>(*begin)) || (*begin == '-' && !plus)))
    return std::nullopt;
  int64_t v = 0;
  const auto [stop, ec] = std::from_chars(begin, end, v, 10);
  if (ec != std::errc() || stop != end) return std::nullopt;
  return v;
}

namespace detail {

std::string join_path(const std::string& prefix, const std::string& key) {
  return prefix.empty() ? key : prefix + "." + key;
}

void type_error(const std::string& path, const YAML::Node& node, const char* expected) {
  std::string got;
  if (node.IsScalar())
    got = "'" + node.Scalar() + "'";
  else if (node.IsSequence())
    got = "a list";
  else if (node.IsMap())
    got = "a section";
  else
    got = "nothing";
  fail("config key '", path, "' must be ", expected, ", got ", got);
}

bool scalar_to(const YAML::Node& node, bool& out) { return YAML::convert<bool>::decode(node, out); }
bool scalar_to(const YAML::Node& node, int& out) {
  const auto v = decimal_integer(node.Scalar());
  if (!v || *v < std::numeric_limits<int>::min() || *v > std::numeric_limits<int>::max())
    return false;
  out = int(*v);
  return true;
}
bool scalar_to(const YAML::Node& node, int64_t& out) {
  const auto v = decimal_integer(node.Scalar());
  if (v) out = *v;
  return v.has_value();
}
bool scalar_to(const YAML::Node& node, double& out) {
  return YAML::convert<double>::decode(node, out);
}
bool scalar_to(const YAML::Node& node, float& out) {
  return YAML::convert<float>::decode(node, out);
}
bool scalar_to(const YAML::Node& node, std::string& out) {
  out = node.Scalar();
  return true;
}

}  // namespace detail
}  // namespace th::config

namespace th::config {
namespace {

void collect_leaves(const YAML::Node& node, const std::string& prefix,
                    std::map<std::string, std::string>& out) {
  if (node.IsMap()) {
    for (const auto& kv : node)
      collect_leaves(kv.second, detail::join_path(prefix, kv.first.as<std::string>()), out);
  } else {
    out[prefix] = YAML::Dump(node);
  }
}

}  // namespace

std::map<std::string, std::string> leaves(const YAML::Node& tree, const std::string& prefix) {
  std::map<std::string, std::string> out;
  collect_leaves(tree, prefix, out);
  return out;
}

}  // namespace th::config
