#include "inference/request.hpp"

#include <algorithm>
#include <filesystem>
#include <map>
#include <vector>

#include "core/config_io.hpp"
#include "model/precision.hpp"

namespace th::inference {
namespace fs = std::filesystem;
namespace {

// Keys of the config that do not change a frame's pixels: training only, where caches live,
// what is checked rather than computed, and the loader's threads. Every other data.*, model.*
// and render.* key is part of a request (a key added later counts until it is listed here).
bool changes_pixels(const std::string& key) {
  static const std::vector<std::string> kNot{"data.train_setting",
                                             "data.test_setting",
                                             "data.calibration_check",
                                             "data.border_band",
                                             "data.patch.",
                                             "data.jitter.",
                                             "data.workers",
                                             "data.prefetch",
                                             "model.encoder.pretrained",
                                             "model.grouping.cache_dir",
                                             "render.train_chunk_points",
                                             "render.train_recompute"};
  for (const auto& k : kNot)
    if (key == k || (k.back() == '.' && key.rfind(k, 0) == 0)) return false;
  return true;
}

// The config's paths, absolute and normal (the same files however they were named); an empty
// path (the documented default) and "compute" stay as they are.
std::map<std::string, std::string> config_paths(const Config& c) {
  std::map<std::string, std::string> paths{
      {"data.root", c.data.root},
      {"data.split_file", c.data.split_file},
      {"data.smpl_model", c.data.smpl_model},
      {"data.visibility_root", c.data.visibility_root},
      {"model.grouping.kmeans_file", c.model.grouping.kmeans_file}};
  for (auto& [key, value] : paths)
    if (!value.empty() && value != kKMeansCompute)
      value = fs::absolute(value).lexically_normal().string();
  return paths;
}

}  // namespace

void emit_pixel_settings(YAML::Emitter& y, const Config& c, const torch::Device& device) {
  y << YAML::BeginMap;
  y << YAML::Key << "precision" << YAML::Value
    << model::resolve_products(c.precision, c.fp32_products, device).describe();
  y << YAML::Key << "eval.setting" << YAML::Value << c.eval.setting;
  const YAML::Node tree = config::to_tree(c);
  const auto paths = config_paths(c);
  for (const char* section : {"data", "model", "render"})
    for (const auto& [key, value] : config::leaves(tree[section], section)) {
      if (!changes_pixels(key)) continue;
      const auto path = paths.find(key);
      y << YAML::Key << key << YAML::Value << (path != paths.end() ? path->second : value);
    }
  y << YAML::EndMap;
}

std::string request_differences(const std::string& before, const std::string& now,
                                const std::string& outputs) {
  std::map<std::string, std::string> old_keys, new_keys;
  try {
    old_keys = config::leaves(YAML::Load(before), "");
    new_keys = config::leaves(YAML::Load(now), "");
  } catch (const YAML::Exception&) {
    return "";
  }
  std::vector<std::string> named;
  auto name = [](const std::string& key) {
    return key.rfind("settings.", 0) == 0 ? key.substr(9) : key;
  };
  for (const auto& [key, value] : new_keys) {
    const auto it = old_keys.find(key);
    if (it == old_keys.end())
      named.push_back(name(key) + " (" + outputs + ": not recorded, now: " + value + ")");
    else if (it->second != value)
      named.push_back(name(key) + " (" + outputs + ": " + it->second + ", now: " + value + ")");
  }
  for (const auto& [key, value] : old_keys)
    if (!new_keys.count(key))
      named.push_back(name(key) + " (" + outputs + ": " + value + ", now: not set)");
  // Another renderer first: the bake keys that come and go with it say less.
  std::stable_partition(named.begin(), named.end(),
                        [](const std::string& n) { return n.rfind("renderer ", 0) == 0; });
  std::string text;
  for (size_t i = 0; i < named.size() && i < 4; ++i) text += (i ? ", " : "") + named[i];
  if (named.size() > 4) text += " and " + std::to_string(named.size() - 4) + " more";
  return text;
}

}  // namespace th::inference
