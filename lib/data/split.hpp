#pragma once
// Train/test splits (METHOD 1.2) read from data_splits/*.yaml; the schema is documented at the
// top of data_splits/zju_mocap.yaml.

#include <filesystem>
#include <map>
#include <ostream>
#include <string>
#include <vector>

namespace th::data {

// A camera as a split file names it: a plain decimal integer (7) is a calibration index; a quoted
// value ("01") or any other text is a camera's name (data/sequence.hpp).
struct CameraRef {
  std::string text;
  bool index = false;
  bool operator==(const CameraRef& other) const {
    return text == other.text && index == other.index;
  }
};
// As a split file would write it: 7 or "01".
inline std::ostream& operator<<(std::ostream& out, const CameraRef& ref) {
  return ref.index ? out << ref.text : out << '"' << ref.text << '"';
}

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
  bool random_references = false;  // training: draw references per sample
  int num_reference_views = 3;     // with random references
  // Cameras by index or name, resolved per person by data::camera_index (data/sequence.hpp).
  std::vector<CameraRef> reference_views;   // fixed references
  bool all_targets = false;                 // every camera of every frame is a target
  bool targets_exclude_references = false;  // with all_targets: every camera but the references
  std::vector<CameraRef> target_views;
  std::vector<HumanRange> humans;
};

// Reads one setting of a split file. Throws th::Error naming the file and the setting (listing
// the settings the file has) or the malformed key.
SplitSetting load_split(const std::filesystem::path& file, const std::string& setting);
// Names of the settings in a split file.
std::vector<std::string> split_settings(const std::filesystem::path& file);

// The setting used where data.split_file is empty: every person folder under `root` (sorted by
// name), every frame; training draws `num_reference_views` references per sample, the other modes
// leave fixed references to the dataset (data.reference_views, or the cameras most evenly spread
// around the body) and take every other camera as a target.
SplitSetting whole_capture_setting(const std::filesystem::path& root, const std::string& name,
                                   bool training, int num_reference_views);

}  // namespace th::data
