#pragma once
// Typed configuration from YAML (the mechanism; the option tree itself is in config.hpp).
//
// A config section is a plain struct with defaults and a `visit_fields` overload that lists its
// fields once; the same list drives parsing (type checks, unknown keys), writing the resolved
// config and documentation:
//
//   struct PatchConfig { int count = 6; int size = 20; double body_prob = 0.8; };
//   template <class V> void visit_fields(V& v, PatchConfig& c) {
//     v("count", c.count);
//     v("size", c.size);
//     v("body_prob", c.body_prob);
//   }
//   template <class V> void visit_fields(V& v, DataConfig& c) {
//     v("patch", c.patch);                                   // nested section
//     v.choice("dataset", c.dataset, {"zju_mocap", "h36m", "synthetic"});
//     v.choice("coordinate", c.coordinate);  // an enum with choice_names (below)
//   }
//
// Field types: bool, int, int64_t, double, float, std::string, std::vector of those, and
// nested structs with their own visit_fields. A struct may also define
// `void validate_section(const T&, const std::string& path)` (found by ADL) that throws
// th::Error for values that are the right type but make no sense together.

#include <yaml-cpp/yaml.h>

#include <cstdint>
#include <filesystem>
#include <initializer_list>
#include <map>
#include <optional>
#include <set>
#include <string>
#include <type_traits>
#include <utility>
#include <vector>

#include "core/error.hpp"

namespace th::config {

// YAML tree of a config file with its parents merged in (key `parent: <file>`, relative to the
// file that names it; chains allowed, cycles refused) and `a.b.c=value` overrides applied
// (value parsed as YAML). An override whose parent path does not exist is refused. With
// `files_read`, the config files read are appended to it as named: `file`, then its parents.
YAML::Node load_tree(const std::filesystem::path& file, const std::vector<std::string>& overrides,
                     std::vector<std::filesystem::path>* files_read = nullptr);
// Applies one `a.b.c=value` override in place. Throws naming the override if malformed.
void apply_override(YAML::Node& root, const std::string& override_text);

// An integer written in decimal: optional sign, digits only ("010" is ten; "0x10", "1e3" and
// " 7" are not integers). Nothing when the text is not one or does not fit in 64 bits. Every
// integer the project reads from a config, a split file or the command line goes through it
// (yaml-cpp and CLI11 on their own would read "010" as octal eight).
std::optional<int64_t> decimal_integer(const std::string& text);

// An enum choice lists its YAML names once, found by argument-dependent lookup:
//   enum class Coordinate { relative, absolute, none };
//   inline const ChoiceNames<Coordinate>& choice_names(Coordinate) {
//     static const ChoiceNames<Coordinate> names{{"relative", Coordinate::relative}, ...};
//     return names;
//   }
// and is read and written by name (v.choice("coordinate", c.coordinate)).
template <class E>
using ChoiceNames = std::vector<std::pair<const char*, E>>;

// The YAML name of an enum choice.
template <class E, std::enable_if_t<std::is_enum_v<E>, int> = 0>
const char* name_of(E value) {
  for (const auto& [name, v] : choice_names(E{}))
    if (v == value) return name;
  return "?";
}

namespace detail {

std::string join_path(const std::string& prefix, const std::string& key);
[[noreturn]] void type_error(const std::string& path, const YAML::Node& node, const char* expected);
bool scalar_to(const YAML::Node& node, bool& out);
bool scalar_to(const YAML::Node& node, int& out);
bool scalar_to(const YAML::Node& node, int64_t& out);
bool scalar_to(const YAML::Node& node, double& out);
bool scalar_to(const YAML::Node& node, float& out);
bool scalar_to(const YAML::Node& node, std::string& out);
template <class T>
const char* type_label();
template <>
inline const char* type_label<bool>() {
  return "a boolean";
}
template <>
inline const char* type_label<int>() {
  return "an integer";
}
template <>
inline const char* type_label<int64_t>() {
  return "an integer";
}
template <>
inline const char* type_label<double>() {
  return "a number";
}
template <>
inline const char* type_label<float>() {
  return "a number";
}
template <>
inline const char* type_label<std::string>() {
  return "a string";
}

template <class T>
constexpr bool is_scalar_v =
    std::is_same_v<T, bool> || std::is_same_v<T, int> || std::is_same_v<T, int64_t> ||
    std::is_same_v<T, double> || std::is_same_v<T, float> || std::is_same_v<T, std::string>;
template <class T>
struct is_vector : std::false_type {};
template <class T>
struct is_vector<std::vector<T>> : std::true_type {};

// ADL hook: sections may define validate_section(const T&, const std::string& path).
template <class T>
auto call_validate(const T& value, const std::string& path, int)
    -> decltype(validate_section(value, path), void()) {
  validate_section(value, path);
}
template <class T>
void call_validate(const T&, const std::string&, long) {}

}  // namespace detail

// Reads a YAML map into a section, checking types and refusing unknown keys.
class Reader {
 public:
  Reader(YAML::Node node, std::string path) : node_(std::move(node)), path_(std::move(path)) {}

  template <class T>
  void operator()(const char* key, T& field) {
    seen_.insert(key);
    const YAML::Node child = node_[key];
    if (!child.IsDefined() || child.IsNull()) return;  // keep the default
    read_value(child, detail::join_path(path_, key), field);
  }

  void choice(const char* key, std::string& field, std::initializer_list<const char*> allowed) {
    (*this)(key, field);
    for (const char* a : allowed)
      if (field == a) return;
    std::string list;
    for (const char* a : allowed) list += std::string(list.empty() ? "" : ", ") + a;
    fail("config key '", detail::join_path(path_, key), "': '", field, "' is not one of {", list,
         "}");
  }

  // A choice parsed once into an enum: the YAML names and their values.
  template <class E, std::enable_if_t<std::is_enum_v<E>, int> = 0>
  void choice(const char* key, E& field) {
    const auto& names = choice_names(E{});
    seen_.insert(key);
    const YAML::Node child = node_[key];
    if (!child.IsDefined() || child.IsNull()) return;  // keep the default
    std::string text;
    read_value(child, detail::join_path(path_, key), text);
    for (const auto& [name, value] : names)
      if (text == name) {
        field = value;
        return;
      }
    std::string list;
    for (const auto& n : names) list += std::string(list.empty() ? "" : ", ") + n.first;
    fail("config key '", detail::join_path(path_, key), "': '", text, "' is not one of {", list,
         "}");
  }

  // Throws naming the first key of the map that no field claimed (with the closest known key).
  void check_unknown() const;

  template <class T>
  static void read_value(const YAML::Node& node, const std::string& path, T& field) {
    if constexpr (detail::is_scalar_v<T>) {
      if (!node.IsScalar() || !detail::scalar_to(node, field))
        detail::type_error(path, node, detail::type_label<T>());
    } else if constexpr (detail::is_vector<T>::value) {
      if (!node.IsSequence()) detail::type_error(path, node, "a list");
      field.clear();
      for (size_t i = 0; i < node.size(); ++i) {
        typename T::value_type item{};
        read_value(node[i], path + "[" + std::to_string(i) + "]", item);
        field.push_back(std::move(item));
      }
    } else {
      if (!node.IsMap()) detail::type_error(path, node, "a section (map)");
      Reader sub(node, path);
      visit_fields(sub, field);
      sub.check_unknown();
      detail::call_validate(field, path, 0);
    }
  }

 private:
  YAML::Node node_;
  std::string path_;
  std::set<std::string> seen_;
};

// Writes a section into a YAML map (every field, defaults included).
class Writer {
 public:
  explicit Writer(YAML::Node node) : node_(std::move(node)) {}

  template <class T>
  void operator()(const char* key, const T& field) {
    node_[key] = to_node(field);
  }
  void choice(const char* key, const std::string& field, std::initializer_list<const char*>) {
    node_[key] = field;
  }
  template <class E, std::enable_if_t<std::is_enum_v<E>, int> = 0>
  void choice(const char* key, const E& field) {
    node_[key] = name_of(field);
  }

  template <class T>
  static YAML::Node to_node(const T& field) {
    if constexpr (detail::is_scalar_v<T>) {
      return YAML::Node(field);
    } else if constexpr (detail::is_vector<T>::value) {
      YAML::Node seq(YAML::NodeType::Sequence);
      for (const auto& item : field) seq.push_back(to_node(item));
      return seq;
    } else {
      YAML::Node map(YAML::NodeType::Map);
      Writer sub(map);
      visit_fields(sub, const_cast<T&>(field));
      return map;
    }
  }

 private:
  YAML::Node node_;
};

// Parses a whole tree into T. `root_path` prefixes key names in errors (empty for the root).
template <class T>
T from_tree(const YAML::Node& tree, const std::string& root_path = "") {
  T value{};
  YAML::Node node = tree;
  if (!node.IsDefined() || node.IsNull()) node = YAML::Node(YAML::NodeType::Map);
  YAML::Node copy = YAML::Clone(node);
  if (copy["parent"]) copy.remove("parent");
  Reader::read_value(copy, root_path, value);
  return value;
}

template <class T>
YAML::Node to_tree(const T& value) {
  return Writer::to_node(value);
}

// load_tree + from_tree.
template <class T>
T load(const std::filesystem::path& file, const std::vector<std::string>& overrides = {}) {
  return from_tree<T>(load_tree(file, overrides));
}

// Writes the resolved config (all fields, defaults included) as YAML. Atomic.
void write_yaml(const std::filesystem::path& file, const YAML::Node& tree);

// Every leaf of a tree as "prefix.a.b" -> its YAML text (sequences are leaves); for comparing
// two configs key by key.
std::map<std::string, std::string> leaves(const YAML::Node& tree, const std::string& prefix);

}  // namespace th::config
