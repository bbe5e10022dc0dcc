#pragma once
// File names of one human's folder in the ZJU-MoCap layout (METHOD 1.1), in its three
// variants: the usual Camera_B{n}/{frame:06d}.jpg + new_params/; CoreView_313/315's
// "Camera (k)" folders with the original long names and 1-based frames; CoreView_396's
// params/ + vertices/.

#include <string>
#include <vector>

#include "synth/person.hpp"

namespace th::synth {

class FolderLayout {
 public:
  // ring_index: ring position of each calibration index (0..22 for 23 cameras).
  FolderLayout(std::string human, FolderStyle style, std::vector<int> ring_index);

  // Folder style from the human's name: CoreView_313/315 -> Original21, CoreView_396 ->
  // Params396, anything else Standard.
  static FolderStyle style_for(const std::string& human);

  int num_cameras() const { return int(ring_index_.size()); }
  const std::vector<int>& ring_index() const { return ring_index_; }
  // Relative to the human's folder; frame is the 0-based index into annots['ims'].
  std::string camera_folder(int camera) const;
  std::string image_path(int frame, int camera) const;
  std::string mask_path(const std::string& kind, int frame,
                        int camera) const;  // kind: mask|mask_cihp
  std::string params_path(int frame) const;
  std::string vertices_path(int frame) const;

 private:
  std::string stem(int frame, int camera) const;
  std::string human_;
  FolderStyle style_;
  std::vector<int> ring_index_;
};

}  // namespace th::synth
