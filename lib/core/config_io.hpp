#pragma once
// Typed configuration from YAML (the mechanism; the option tree itself is in config.hpp).
//
// A config section declares each key once, in one line of its key list: what kind of key it is,
// its C++ type, its name, its default, the values it accepts and a one-line description.
// TH_CONFIG_SECTION makes the section's struct (plain fields with their defaults) and its
// `visit_fields` from the list; that one list drives reading (type and range checks, unknown
// keys), writing the resolved config, and the listing of every key (`--config-keys`):
//
//   #define TH_PATCH_KEYS(X)
//     X(key, int, count, 6, config::in(1, 1024), "patches per training image")
//     X(key, bool, enabled, true, {}, "sample patches at all")        // {}: any value
//     X(choice, DatasetKind, dataset, DatasetKind::synthetic, , "which reader")
//     X(names, std::string, device, "auto", config::names("auto", "cpu"), "where it runs")
//     X(section, JitterConfig, jitter, , , "colour jitter")
//     X(retired, , old_key, , , "why it is no key any more")
//   TH_CONFIG_SECTION(PatchConfig, TH_PATCH_KEYS)
// (each line of the #define but the last ends in a backslash).
//
// Kinds: `key` (a number, string, bool or list; its values a Range, {} for any), `choice` (an
// enum, read and written by the names of its choice_names), `names` (a string from a fixed
// list), `section` (a nested section with its own key list), `retired` (no field: a key that is
// no longer read; its description says why). A default with commas is parenthesised:
// `(std::vector<double>{0.2, 2.0})`.
//
// Field types: bool, int, int64_t, double, float, std::string, std::vector of those, and
// nested sections. Every number read must be finite. A section may also define
// `void validate_section(const T&, const std::string& path)` (found by ADL) that throws th::Error
// for values that are each in range but make no sense together.

#define TH_CONFIG_SECTION(Name, KEYS) \
  struct Name {                       \
    KEYS(TH_CONFIG_FIELD)             \
  };                                  \
  template <class V>                  \
  void visit_fields(V& v, Name& c) {  \
    KEYS(TH_CONFIG_VISIT)             \
  }
#define TH_CONFIG_FIELD(kind, type, name, def, values, doc) TH_CONFIG_FIELD_##kind(type, name, def)
#define TH_CONFIG_FIELD_key(type, name, def) type name = def;
#define TH_CONFIG_FIELD_choice(type, name, def) type name = def;
#define TH_CONFIG_FIELD_names(type, name, def) type name = def;
#define TH_CONFIG_FIELD_section(type, name, def) type name;
#define TH_CONFIG_FIELD_retired(type, name, def)
#define TH_CONFIG_VISIT(kind, type, name, def, values, doc) \
  TH_CONFIG_VISIT_##kind(name, values, doc)
#define TH_CONFIG_VISIT_key(name, values, doc) v(#name, c.name, values, doc);
#define TH_CONFIG_VISIT_choice(name, values, doc) v.choice(#name, c.name, doc);
#define TH_CONFIG_VISIT_names(name, values, doc) v.choice(#name, c.name, values, doc);
#define TH_CONFIG_VISIT_section(name, values, doc) v(#name, c.name, doc);
#define TH_CONFIG_VISIT_retired(name, values, doc) v.retired(#name, doc);

#include <yaml-cpp/yaml.h>

#include <cstdint>
#include <filesystem>
#include <functional>
#include <initializer_list>
#include <limits>
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

// The values a numeric key accepts: an interval, closed or open at each end (its default: any
// finite number).
struct Range {
  double low = -std::numeric_limits<double>::infinity();
  double high = std::numeric_limits<double>::infinity();
  bool low_open = false, high_open = false;

  bool holds(double x) const {
    return (low_open ? x > low : x >= low) && (high_open ? x < high : x <= high);
  }
  bool any() const {
    return low == -std::numeric_limits<double>::infinity() &&
           high == std::numeric_limits<double>::infinity();
  }
  // "in [2, 4096]", ">= 0", "> 0", "in [0, 1)"; empty for any().
  std::string text() const;
};
inline Range in(double low, double high) { return {low, high, false, false}; }       // [low, high]
inline Range in_below(double low, double high) { return {low, high, false, true}; }  // [low, high)
inline Range in_above(double low, double high) { return {low, high, true, false}; }  // (low, high]
inline Range at_least(double low) {
  return {low, std::numeric_limits<double>::infinity(), false, false};
}
inline Range above(double low) {
  return {low, std::numeric_limits<double>::infinity(), true, false};
}

// The names a string key accepts (`names` keys).
using Names = std::vector<const char*>;
template <class... S>
Names names(S... name) {
  return {name...};
}

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

// The enum value of a choice's YAML name; a th::Error naming `what`, `text` and the known names
// otherwise (command-line options that take a choice's names).
template <class E, std::enable_if_t<std::is_enum_v<E>, int> = 0>
E parse_choice(const std::string& what, const std::string& text) {
  std::string list;
  for (const auto& [name, v] : choice_names(E{})) {
    if (text == name) return v;
    list += std::string(list.empty() ? "" : ", ") + name;
  }
  fail(what, ": '", text, "' is not one of {", list, "}");
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
  void operator()(const char* key, T& field, const char* doc = "") {
    (*this)(key, field, Range{}, doc);
  }
  // Reads the key (the default stays when it is absent) and checks the value against `range`.
  template <class T>
  void operator()(const char* key, T& field, const Range& range, const char* doc) {
    seen_.insert(key);
    const YAML::Node child = node_[key];
    if (!child.IsDefined() || child.IsNull()) return;  // keep the default
    const std::string path = detail::join_path(path_, key);
    read_value(child, path, field);
    check_numbers(path, field, range, doc);
  }

  void choice(const char* key, std::string& field, const Names& allowed, const char* doc = "") {
    (*this)(key, field, doc);
    for (const char* a : allowed)
      if (field == a) return;
    std::string list;
    for (const char* a : allowed) list += std::string(list.empty() ? "" : ", ") + a;
    fail("config key '", detail::join_path(path_, key), "': '", field, "' is not one of {", list,
         "}");
  }

  // A choice parsed once into an enum: the YAML names and their values.
  template <class E, std::enable_if_t<std::is_enum_v<E>, int> = 0>
  void choice(const char* key, E& field, const char* = "") {
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

  // A key that is no longer read (it never changed what a config computes): present, it is
  // ignored with one warning naming it and `why`; absent, nothing happens.
  void retired(const char* key, const char* why);

  // Throws naming the first key of the map that no field claimed (with the closest known key).
  void check_unknown() const;
  // Throws naming the key when `value` is not finite or outside `range` (with the key's `doc`).
  static void check_range(const std::string& path, double value, const Range& range,
                          const char* doc);
  // check_range on every number of `field` (a number or a list; nothing for other types).
  template <class T>
  static void check_numbers(const std::string& path, const T& field, const Range& range,
                            const char* doc) {
    if constexpr (std::is_arithmetic_v<T> && !std::is_same_v<T, bool>) {
      check_range(path, double(field), range, doc);
    } else if constexpr (detail::is_vector<T>::value) {
      for (size_t i = 0; i < field.size(); ++i)
        check_numbers(path + "[" + std::to_string(i) + "]", field[i], range, doc);
    }
  }

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
  void operator()(const char* key, const T& field, const char* = "") {
    node_[key] = to_node(field);
  }
  template <class T>
  void operator()(const char* key, const T& field, const Range&, const char*) {
    node_[key] = to_node(field);
  }
  void choice(const char* key, const std::string& field, const Names&, const char* = "") {
    node_[key] = field;
  }
  template <class E, std::enable_if_t<std::is_enum_v<E>, int> = 0>
  void choice(const char* key, const E& field, const char* = "") {
    node_[key] = name_of(field);
  }
  void retired(const char*, const char*) {}

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

// Checks a section built in code as reading it would: every number finite and in its declared
// range, and each section's validate_section.
class Checker {
 public:
  explicit Checker(std::string path) : path_(std::move(path)) {}

  template <class T>
  void operator()(const char* key, const T& field, const char* doc = "") {
    (*this)(key, field, Range{}, doc);
  }
  template <class T>
  void operator()(const char* key, const T& field, const Range& range, const char* doc) {
    const std::string path = detail::join_path(path_, key);
    if constexpr (detail::is_scalar_v<T> || detail::is_vector<T>::value)
      Reader::check_numbers(path, field, range, doc);
    else
      check(field, path);
  }
  // Choices: an enum holds one of its names by construction; a string is checked as read.
  void choice(const char*, const std::string&, const Names&, const char* = "") {}
  template <class E, std::enable_if_t<std::is_enum_v<E>, int> = 0>
  void choice(const char*, const E&, const char* = "") {}
  void retired(const char*, const char*) {}

  template <class T>
  static void check(const T& value, const std::string& path) {
    Checker sub(path);
    visit_fields(sub, const_cast<T&>(value));
    detail::call_validate(value, path, 0);
  }

 private:
  std::string path_;
};

// Checker::check: `value` (a section built in code) as reading it from YAML would check it.
template <class T>
void check(const T& value, const std::string& path) {
  Checker::check(value, path);
}

// One declared key: its full name, what it holds, its default, the values it accepts and its
// description (the listing of --config-keys, and the tests that every key is documented and its
// range enforced).
struct KeyInfo {
  std::string key;      // "render.samples"
  std::string type;     // "an integer", "a list", "one of {fp32, bf16, auto}"
  std::string value;    // the default, as YAML
  std::string accepts;  // "in [2, 4096]"; empty: any value of the type
  std::string doc;
  Range range;  // numbers only
};

// Collects KeyInfo for every leaf field of a section (nested sections are walked).
class Lister {
 public:
  explicit Lister(std::vector<KeyInfo>& out, std::string path = "")
      : out_(out), path_(std::move(path)) {}

  template <class T>
  void operator()(const char* key, const T& field, const char* doc = "") {
    (*this)(key, field, Range{}, doc);
  }
  template <class T>
  void operator()(const char* key, const T& field, const Range& range, const char* doc) {
    const std::string path = detail::join_path(path_, key);
    if constexpr (!detail::is_scalar_v<T> && !detail::is_vector<T>::value) {
      Lister sub(out_, path);
      visit_fields(sub, const_cast<T&>(field));
    } else {
      std::string type;
      if constexpr (detail::is_scalar_v<T>)
        type = detail::type_label<T>();
      else
        type = "a list";
      add(path, type, Writer::to_node(field), range, doc);
    }
  }
  void choice(const char* key, const std::string& field, const Names& allowed,
              const char* doc = "") {
    std::string list;
    for (const char* a : allowed) list += std::string(list.empty() ? "" : ", ") + a;
    add(detail::join_path(path_, key), "one of {" + list + "}", YAML::Node(field), Range{}, doc);
  }
  template <class E, std::enable_if_t<std::is_enum_v<E>, int> = 0>
  void choice(const char* key, const E& field, const char* doc = "") {
    std::string list;
    for (const auto& n : choice_names(E{})) list += std::string(list.empty() ? "" : ", ") + n.first;
    add(detail::join_path(path_, key), "one of {" + list + "}", YAML::Node(name_of(field)), Range{},
        doc);
  }
  void retired(const char*, const char*) {}  // not a key any more: not listed

 private:
  void add(const std::string& path, const std::string& type, const YAML::Node& value,
           const Range& range, const char* doc);
  std::vector<KeyInfo>& out_;
  std::string path_;
};

// Every key of section type T with its default (a default-constructed T).
template <class T>
std::vector<KeyInfo> keys() {
  std::vector<KeyInfo> out;
  T value{};
  Lister lister(out);
  visit_fields(lister, value);
  return out;
}

// The keys as a text table: one line per key (name, type, default, accepted values, description).
std::string describe(const std::vector<KeyInfo>& keys);

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
