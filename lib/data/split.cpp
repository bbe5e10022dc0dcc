#include "data/split.hpp"

#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cstdio>
#include <limits>
#include <optional>
#include <type_traits>

#include "core/config_io.hpp"
#include "core/error.hpp"
#include "core/files.hpp"

namespace th::data {
namespace {

YAML::Node load_settings(const std::filesystem::path& file) {
  refuse_special_file(file, "split file");
  if (!std::filesystem::is_regular_file(file))
    fail("split file '", file.string(), "' does not exist");
  YAML::Node root;
  try {
    root = YAML::LoadFile(file.string());
  } catch (const YAML::Exception& e) {
    fail("split file '", file.string(), "': YAML error at line ", e.mark.line + 1, ": ", e.msg);
  }
  if (!root["settings"] || !root["settings"].IsMap())
    fail("split file '", file.string(), "' has no 'settings' map");
  return root["settings"];
}

template <class T>
T get(const YAML::Node& node, const char* key, const std::string& where) {
  if (!node[key]) fail(where, ": missing '", key, "'");
  if constexpr (std::is_same_v<T, int>) {
    // Decimal, as every integer of a config ("010" is ten, not yaml-cpp's octal eight).
    const auto v =
        node[key].IsScalar() ? config::decimal_integer(node[key].Scalar()) : std::nullopt;
    if (!v || *v < std::numeric_limits<int>::min() || *v > std::numeric_limits<int>::max())
      fail(where, ": '", key, "' must be a decimal integer");
    return int(*v);
  } else {
    try {
      return node[key].as<T>();
    } catch (const YAML::Exception&) {
      fail(where, ": '", key, "' has the wrong type");
    }
  }
}

// A person's name is a folder under the dataset root and a cell of per_image.csv: a control
// character (a line break would split the CSV row and the log line) or a first character that
// spreadsheets read as a formula (= + - @) is refused before any work.
void check_person_name(const std::string& name, const std::string& where) {
  for (const char c : name)
    if (static_cast<unsigned char>(c) < 0x20 || c == 0x7f) {
      char code[8];
      std::snprintf(code, sizeof code, "0x%02x", static_cast<unsigned char>(c));
      fail(where, ": the person's name holds a control character (", code,
           "); names are folder names without them");
    }
  if (name.empty()) fail(where, ": the person's name is empty");
  if (std::string("=+-@").find(name.front()) != std::string::npos)
    fail(where, ": the person's name '", name, "' starts with '", name.front(),
         "', which spreadsheets read as a formula (per_image.csv); rename the folder");
}

// A view list: [camera, ...] (indices or names), or the keyword (`random` / `all`) or an empty
// list for it.
bool read_views(const YAML::Node& node, const char* key, const char* keyword,
                std::vector<CameraRef>& views, const std::string& where) {
  const YAML::Node v = node[key];
  if (!v) fail(where, ": missing '", key, "'");
  if (v.IsScalar() && v.Scalar() == keyword) return true;
  if (!v.IsSequence())
    fail(where, ": '", key, "' must be a list of cameras (indices or names) or '", keyword, "'");
  views.clear();
  for (const auto& item : v) {
    if (!item.IsScalar() || item.Scalar().empty())
      fail(where, ": '", key, "' must be a list of cameras (calibration indices or camera names)");
    // yaml-cpp tags a quoted scalar "!" and a plain one "?".
    const bool plain = item.Tag() != "!";
    const auto number = config::decimal_integer(item.Scalar());
    views.push_back({item.Scalar(), plain && number.has_value()});
  }
  return views.empty();
}

}  // namespace

std::vector<int> HumanRange::frames(int num_frames) const {
  std::vector<int> out;
  const int64_t end = std::min<int64_t>(int64_t(begin) + ni, num_frames);
  for (int64_t f = begin; f < end; f += interval) out.push_back(int(f));
  return out;
}

std::vector<std::string> split_settings(const std::filesystem::path& file) {
  std::vector<std::string> names;
  for (const auto& kv : load_settings(file)) names.push_back(kv.first.as<std::string>());
  return names;
}

SplitSetting load_split(const std::filesystem::path& file, const std::string& name) {
  const YAML::Node settings = load_settings(file);
  const YAML::Node node = settings[name];
  if (!node) {
    std::string known;
    for (const auto& kv : settings)
      known += (known.empty() ? "" : ", ") + kv.first.as<std::string>();
    fail("split file '", file.string(), "' has no setting '", name, "' (it has: ", known, ")");
  }
  const std::string where = "split file '" + file.string() + "', setting '" + name + "'";
  SplitSetting s;
  s.name = name;
  s.random_references = read_views(node, "reference_views", "random", s.reference_views, where);
  if (s.random_references) s.num_reference_views = get<int>(node, "num_reference_views", where);
  s.all_targets = read_views(node, "target_views", "all", s.target_views, where);

  if (node["humans_from"]) {
    const auto base = load_split(file, node["humans_from"].as<std::string>());
    s.humans = base.humans;
    if (node["interval"])
      for (auto& h : s.humans) h.interval = get<int>(node, "interval", where);
  } else {
    const YAML::Node humans = node["humans"];
    if (!humans || !humans.IsSequence() || humans.size() == 0)
      fail(where, ": 'humans' must be a non-empty list");
    for (size_t i = 0; i < humans.size(); ++i) {
      const std::string w = where + ", humans[" + std::to_string(i) + "]";
      const char* name_key = humans[i]["human"] ? "human" : "name";
      HumanRange h{get<std::string>(humans[i], name_key, w), get<int>(humans[i], "begin", w),
                   get<int>(humans[i], "ni", w), get<int>(humans[i], "interval", w)};
      check_person_name(h.name, w);
      if (h.begin < 0 || h.ni <= 0 || h.interval <= 0)
        fail(w, ": begin must be >= 0, ni and interval > 0");
      s.humans.push_back(h);
    }
  }
  if (!s.random_references && s.reference_views.empty()) fail(where, ": no reference views");
  if (!s.all_targets && s.target_views.empty()) fail(where, ": no target views");
  return s;
}

SplitSetting whole_capture_setting(const std::filesystem::path& root, const std::string& name,
                                   bool training, int num_reference_views) {
  namespace fs = std::filesystem;
  std::error_code ec;
  if (!fs::is_directory(root, ec)) fail("data.root '", root.string(), "' does not exist");
  SplitSetting s;
  s.name = name;
  s.random_references = training;
  s.num_reference_views = num_reference_views;
  s.all_targets = true;
  s.targets_exclude_references = !training;
  std::vector<std::string> people;
  for (const auto& entry : fs::directory_iterator(root)) {
    const fs::path dir = entry.path();
    if (!entry.is_directory(ec)) continue;
    // What data::detect_layout reads (either calibration file: the reader names the other).
    if (fs::exists(dir / "annots.npy", ec) || fs::exists(dir / "intri.yml", ec) ||
        fs::exists(dir / "extri.yml", ec) || fs::exists(dir / "Posing" / "annots.npy", ec))
      people.push_back(dir.filename().string());
  }
  std::sort(people.begin(), people.end());
  if (people.empty())
    fail("data.root '", root.string(),
         "' holds no person's folder (one with annots.npy, or intri.yml and extri.yml), ",
         "and data.split_file is empty");
  for (const auto& p : people) {
    check_person_name(p, "data.root '" + root.string() + "'");
    s.humans.push_back({p, 0, std::numeric_limits<int>::max(), 1});
  }
  return s;
}

}  // namespace th::data
