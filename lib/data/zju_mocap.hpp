#pragma once
// ZJU-MoCap as users download it (METHOD 1.1), read straight from its folder layout. H36M
// (Animatable NeRF's preprocessing) has the same layout per subject and is read by the same code
// (data/h36m.hpp).
//
// A human's folder holds:
//   annots.npy                          cams {K, R, T (mm), D} per camera, ims[frame]['ims']
//   <camera folder>/<image>             one image per camera and frame, as listed in annots
//   mask/<same path>.png, mask_cihp/<same path>.png    at least one of the two
//   new_params/<n>.npy, new_vertices/<n>.npy           (or params/, vertices/ as CoreView_396)
// where <n> is the frame number in the image name. CoreView_313/315's original long names
// (CoreView_313_Camera_(1)_0001_2019-...jpg) and their renamed form (0001.jpg) both resolve.

#include <filesystem>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <vector>

#include "data/sequence.hpp"

namespace th::data {

// A camera's name is the folder of its images (Camera_B1, "Camera (1)").
class ZjuMocapSequence final : public HumanSequence {
 public:
  // Reads <dir>/annots.npy. Throws th::Error naming the file and what is missing.
  static std::shared_ptr<ZjuMocapSequence> open(const std::filesystem::path& dir);

  const char* layout() const override { return "zju_mocap"; }
  std::filesystem::path calibration_file() const override { return dir() / "annots.npy"; }
  int num_frames() const override { return int(ims_.size()); }
  // Image file of (frame, camera), resolving renamed/original names. Throws naming the path.
  std::filesystem::path image_path(int frame, int camera) const override;
  // The number in the image's name: params/vertices are <number>.npy.
  int frame_number(int frame) const override;
  BodyParams load_params(int frame) const override;
  torch::Tensor load_vertices(int frame) const override;
  // mask/ and mask_cihp/, whichever exist.
  std::vector<std::filesystem::path> mask_files(int frame, int camera) const override;

 private:
  ZjuMocapSequence(std::string name, std::filesystem::path dir)
      : HumanSequence(std::move(name), std::move(dir)) {}
  // A file listed relative to the human's folder, also under the renamed/original name of the
  // same frame number; resolve throws naming the path where find returns nothing.
  std::filesystem::path resolve(const std::filesystem::path& relative) const;
  std::optional<std::filesystem::path> find(const std::filesystem::path& relative) const;
  std::filesystem::path body_file(const char* kind, const char* legacy, int frame) const;

  std::vector<std::vector<std::string>> ims_;  // [frame][camera], relative to dir_
  mutable std::mutex cache_mutex_;
  mutable std::map<std::filesystem::path, std::map<int, std::string>> folder_index_;
};

// The frame number of an image name: "000123.jpg" -> 123, "0001.jpg" -> 1,
// "CoreView_313_Camera_(1)_0001_2019-08-23_16-08-50.592.jpg" -> 1. -1 if it has none.
int frame_number_of(const std::string& filename);

// NHP's zju_rasterization layout of precomputed SMPL visibility (METHOD 1.1), as the reference
// reads it: <root>/<human>/visibility/<camera folder>/<frame number>.npy, the number zero-padded
// like the renamed images (an all-digit image name gives the width, e.g. 000123.jpg -> 6;
// CoreView_313/315's original long names -> 4), whatever the image files are called.
std::filesystem::path visibility_file(const std::filesystem::path& root, const HumanSequence& human,
                                      int frame, int camera);

}  // namespace th::data
