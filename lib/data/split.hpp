#pragma once
// Train/test splits (METHOD 1.2) read from data_splits/*.yaml; the schema is documented at the
// top of data_splits/zju_mocap.yaml.

#include <filesystem>
#include <map>
#include <string>
#include <vector>

namespace th::data {

struct HumanRange {
  std::string name;  // folder under the dataset root
  int begin = 0;
  int ni = 0;
  int interval = 1;
  // Frame indices into annots' ims: ims[begin : begin+ni][::interval], clipped to num_frames.
  std::vector<int> frames(int num_frames) const;
};

struct SplitSetting {
  std::string name;
  bool random_references = false;   // training: draw references per sample
  int num_reference_views = 3;      // with random references
  std::vector<int> reference_views; // fixed references
  bool all_targets = false;         // every camera of every frame is a target
  std::vector<int> target_views;
  std::vector<HumanRange> humans;
};

// Reads one setting of a split file. Throws th::Error naming the file and the setting (listing
// the settings the file has) or the malformed key.
SplitSetting load_split(const std::filesystem::path& file, const std::string& setting);
// Names of the settings in a split file.
std::vector<std::string> split_settings(const std::filesystem::path& file);

}  // namespace th::data
