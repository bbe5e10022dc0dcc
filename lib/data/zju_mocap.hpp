#pragma once
// ZJU-MoCap as users download it (METHOD 1.1), read straight from its folder layout, and the
// per-view image preprocessing of METHOD 2.1. H36M (Animatable NeRF's preprocessing) has the same
// layout per subject and is read by the same code (data/h36m.hpp).
//
// A human's folder holds:
//   annots.npy                          cams {K, R, T (mm), D} per camera, ims[frame]['ims']
//   <camera folder>/<image>             one image per camera and frame, as listed in annots
//   mask/<same path>.png, mask_cihp/<same path>.png    at least one of the two
//   new_params/<n>.npy, new_vertices/<n>.npy           (or params/, vertices/ as CoreView_396)
// where <n> is the frame number in the image name. CoreView_313/315's original long names
// (CoreView_313_Camera_(1)_0001_2019-...jpg) and their renamed form (0001.jpg) both resolve.

#include <opencv2/core.hpp>
#include <torch/types.h>

#include <filesystem>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <vector>

#include "data/jitter.hpp"

namespace th::data {

// One calibrated camera; T in metres (annots.npy stores millimetres).
struct Camera {
  torch::Tensor K;  // (3, 3) float64, pixels of the image as stored on disk
  torch::Tensor R;  // (3, 3) float64, world -> camera
  torch::Tensor T;  // (3, 1) float64, metres
  torch::Tensor D;  // (5, 1) float64, OpenCV k1, k2, p1, p2, k3
};

// SMPL parameters of one frame (new_params/<n>.npy).
struct BodyParams {
  torch::Tensor poses;   // (72) float64 axis-angle
  torch::Tensor Rh;      // (3) float64 axis-angle, global rotation
  torch::Tensor Th;      // (3) float64 metres
  torch::Tensor shapes;  // (S) float64
};

class HumanSequence {
 public:
  // Reads <dir>/annots.npy. Throws th::Error naming the file and what is missing.
  static std::shared_ptr<HumanSequence> open(const std::filesystem::path& dir);

  const std::string& name() const { return name_; }
  const std::filesystem::path& dir() const { return dir_; }
  int num_frames() const { return int(ims_.size()); }
  int num_cameras() const { return int(cameras_.size()); }
  const Camera& camera(int index) const;

  // Image file of (frame, camera), resolving renamed/original names. Throws naming the path.
  std::filesystem::path image_path(int frame, int camera) const;
  // The number in the image's name: params/vertices are <number>.npy.
  int frame_number(int frame) const;
  BodyParams load_params(int frame) const;
  torch::Tensor load_vertices(int frame) const;  // (V, 3) float64 world coordinates
  // Union of mask/ and mask_cihp/ at the image's resolution, CV_8U 0/1 (before undistortion).
  cv::Mat load_mask(int frame, int camera) const;

 private:
  HumanSequence() = default;
  // A file listed relative to the human's folder, also under the renamed/original name of the
  // same frame number; resolve throws naming the path where find returns nothing.
  std::filesystem::path resolve(const std::filesystem::path& relative) const;
  std::optional<std::filesystem::path> find(const std::filesystem::path& relative) const;
  std::filesystem::path body_file(const char* kind, const char* legacy, int frame) const;

  std::string name_;
  std::filesystem::path dir_;
  std::vector<Camera> cameras_;
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

// One view after METHOD 2.1: undistorted, resized by `ratio`, background black.
struct ViewImage {
  cv::Mat rgb;   // CV_32FC3, RGB in [0, 1]
  // CV_8U: 0 background, 1 person, 100 border band (target views only). With the band marked
  // before undistortion [parity], edge pixels hold bilinear blends of 0, 1 and 100.
  cv::Mat mask;
  Camera camera; // K scaled by ratio (no half-pixel shift), T in metres
};

struct ViewOptions {
  double ratio = 0.5;
  bool border_band = false;         // target views: mark dilate5x5 - erode5x5 with 100
  const JitterParams* jitter = nullptr;
  // METHOD 2.1 step 6 [parity]: the band is marked on the distorted mask, which is then undistorted
  // (bilinear); false: marked on the undistorted mask (a clean 0/1/100 mask).
  bool band_before_undistort = true;
};
ViewImage load_view(const HumanSequence& human, int frame, int camera, const ViewOptions& options);

}  // namespace th::data
