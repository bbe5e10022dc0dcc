#include "synth/layout.hpp"

#include <cstdio>

namespace th::synth {

FolderLayout::FolderLayout(std::string human, FolderStyle style, std::vector<int> ring_index)
    : human_(std::move(human)), style_(style), ring_index_(std::move(ring_index)) {}

FolderStyle FolderLayout::style_for(const std::string& human) {
  if (human == "CoreView_313" || human == "CoreView_315") return FolderStyle::Original21;
  if (human == "CoreView_396") return FolderStyle::Params396;
  return FolderStyle::Standard;
}

std::string FolderLayout::camera_folder(int camera) const {
  const int k = ring_index_.at(camera) + 1;
  if (style_ == FolderStyle::Original21) return "Camera (" + std::to_string(k) + ")";
  return "Camera_B" + std::to_string(k);
}

std::string FolderLayout::stem(int frame, int camera) const {
  char buf[160];
  if (style_ == FolderStyle::Original21) {
    // e.g. CoreView_313_Camera_(1)_0001_2019-08-23_16-08-50.592: a 50 fps capture whose
    // cameras' clocks differ by a few milliseconds.
    const int k = ring_index_.at(camera) + 1;
    const long ms = 58130592L + 20L * frame + (7L * k) % 13;  // 16:08:50.592 + ...
    std::snprintf(buf, sizeof(buf), "%s_Camera_(%d)_%04d_2019-08-23_%02ld-%02ld-%02ld.%03ld",
                  human_.c_str(), k, frame + 1, ms / 3600000, (ms / 60000) % 60, (ms / 1000) % 60,
                  ms % 1000);
  } else {
    std::snprintf(buf, sizeof(buf), "%06d", frame);
  }
  return buf;
}

std::string FolderLayout::image_path(int frame, int camera) const {
  return camera_folder(camera) + "/" + stem(frame, camera) + ".jpg";
}

std::string FolderLayout::mask_path(const std::string& kind, int frame, int camera) const {
  return kind + "/" + camera_folder(camera) + "/" + stem(frame, camera) + ".png";
}

std::string FolderLayout::params_path(int frame) const {
  // 313/315: 0001.jpg <-> params/1.npy (METHOD 1.1).
  const int i = style_ == FolderStyle::Original21 ? frame + 1 : frame;
  return std::string(style_ == FolderStyle::Params396 ? "params/" : "new_params/") +
         std::to_string(i) + ".npy";
}

std::string FolderLayout::vertices_path(int frame) const {
  const int i = style_ == FolderStyle::Original21 ? frame + 1 : frame;
  return std::string(style_ == FolderStyle::Params396 ? "vertices/" : "new_vertices/") +
         std::to_string(i) + ".npy";
}

}  // namespace th::synth
