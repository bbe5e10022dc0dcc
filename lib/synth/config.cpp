#include "synth/config.hpp"

#include "core/error.hpp"
#include "synth/generator.hpp"

namespace th::synth {

// Checks across keys; each key's own range is declared with it (config.hpp).
void validate_section(const SynthConfig& c, const std::string& path) {
  auto key = [&](const char* k) { return path.empty() ? std::string(k) : path + "." + k; };
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
  if (c.split.train_frames > c.frames)
    fail("config key '", key("split.train_frames"), "': must be in [1, frames = ", c.frames,
         "], got ", c.split.train_frames);
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
