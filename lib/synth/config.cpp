#include "synth/config.hpp"

#include <utility>

#include "core/error.hpp"
#include "synth/generator.hpp"

namespace th::synth {

void validate_section(const SynthConfig& c, const std::string& path) {
  auto key = [&](const char* k) { return path.empty() ? std::string(k) : path + "." + k; };
  if (c.layout != "zju_mocap" && c.layout != "easymocap")
    fail("config key '", key("layout"), "': must be zju_mocap or easymocap, got '", c.layout, "'");
  if (c.frames < 1) fail("config key '", key("frames"), "': must be >= 1, got ", c.frames);
  if (c.threads < 1) fail("config key '", key("threads"), "': must be >= 1, got ", c.threads);
  if (c.people.train.empty() && c.people.unseen.empty())
    fail("config key '", key("people"), "': no people to generate");
  std::vector<std::string> names = c.people.train;
  names.insert(names.end(), c.people.unseen.begin(), c.people.unseen.end());
  for (size_t i = 0; i < names.size(); ++i) {
    if (names[i].empty() || names[i].find_first_of("/\\ ") != std::string::npos ||
        names[i] == "." || names[i] == "..")
      fail("config key '", key("people"), "': '", names[i], "' is not a folder name");
    for (size_t j = 0; j < i; ++j)
      if (names[i] == names[j]) fail("config key '", key("people"), "': '", names[i], "' twice");
  }
  if (c.cameras.count < 1 || c.cameras.count > 99)
    fail("config key '", key("cameras.count"), "': must be in [1, 99], got ", c.cameras.count);
  if (c.image.width < 16 || c.image.height < 16)
    fail("config key '", key("image"), "': images must be at least 16x16, got ", c.image.width, "x",
         c.image.height);
  if (c.image.supersample < 1 || c.image.supersample > 4)
    fail("config key '", key("image.supersample"), "': must be in [1, 4], got ",
         c.image.supersample);
  if (c.image.jpeg_quality < 1 || c.image.jpeg_quality > 100)
    fail("config key '", key("image.jpeg_quality"), "': must be in [1, 100], got ",
         c.image.jpeg_quality);
  if (c.split.train_frames < 1 || c.split.train_frames > c.frames)
    fail("config key '", key("split.train_frames"), "': must be in [1, frames = ", c.frames,
         "], got ", c.split.train_frames);
  for (auto [name, v] : {std::pair{"split.pose_interval", c.split.pose_interval},
                         {"split.test_interval", c.split.test_interval},
                         {"split.fitting_interval", c.split.fitting_interval}})
    if (v < 1) fail("config key '", key(name), "': must be >= 1, got ", v);
}

std::string config_text(const SynthConfig& config) {
  YAML::Node tree = config::to_tree(config);
  // The default layout is left out, so a dataset written before the key existed is still the
  // same dataset.
  if (config.layout == "zju_mocap") tree.remove("layout");
  YAML::Emitter e;
  e << tree;
  return std::string("# transhuman-synth: the resolved configuration of this dataset.\n") +
         e.c_str() + "\n";
}

}  // namespace th::synth
