#pragma once
// One person's capture as the rest of the project sees it, whatever layout holds it on disk
// (METHOD 1.1): calibrated cameras with names, frames, images and masks, and the SMPL fit of
// each frame. Two layouts are read: ZJU-MoCap's (data/zju_mocap.hpp; H36M as preprocessed by
// Animatable NeRF too) and EasyMocap's (data/easymocap.hpp), the one own captures come in.

#include <torch/types.h>

#include <filesystem>
#include <memory>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "core/config.hpp"
#include "data/jitter.hpp"

namespace th::body {
struct SmplModel;
}

namespace th::data {

// One calibrated camera, world to camera X_c = R X + T.
struct Camera {
  torch::Tensor K;  // (3, 3) float64, pixels of the image as stored on disk
  torch::Tensor R;  // (3, 3) float64, world -> camera
  torch::Tensor T;  // (3, 1) float64, metres
  torch::Tensor D;  // (5, 1) float64, OpenCV k1, k2, p1, p2, k3
};

// SMPL parameters of one frame: world vertices = Rodrigues(Rh) LBS(poses, shapes) + Th.
struct BodyParams {
  torch::Tensor poses;   // (72) float64 axis-angle
  torch::Tensor Rh;      // (3) float64 axis-angle, global rotation
  torch::Tensor Th;      // (3) float64 metres
  torch::Tensor shapes;  // (S) float64
};

class HumanSequence {
 public:
  virtual ~HumanSequence() = default;

  const std::string& name() const { return name_; }
  const std::filesystem::path& dir() const { return dir_; }
  virtual const char* layout() const = 0;  // "zju_mocap" | "easymocap"
  // The file the calibration comes from, named in messages about it.
  virtual std::filesystem::path calibration_file() const = 0;

  virtual int num_frames() const = 0;
  int num_cameras() const { return int(cameras_.size()); }
  // Throws th::Error naming the person and the number of cameras for an index out of range.
  const Camera& camera(int index) const;
  const std::string& camera_name(int index) const;

  // Image file of (frame, camera). Throws naming the path when it is missing.
  virtual std::filesystem::path image_path(int frame, int camera) const = 0;
  // The number in the frame's file names (ZJU-MoCap's params/<n>.npy, EasyMocap's <n>.json).
  virtual int frame_number(int frame) const = 0;
  virtual BodyParams load_params(int frame) const = 0;
  // (V, 3) float64 world vertices of the frame's fit.
  virtual torch::Tensor load_vertices(int frame) const = 0;
  // The mask files of (frame, camera) that exist, read in this order (ZJU-MoCap: mask/ and
  // mask_cihp/; EasyMocap: mask/ and masks/). Throws naming where it looked when none does.
  virtual std::vector<std::filesystem::path> mask_files(int frame, int camera) const = 0;
  // The person's mask at the image's resolution, CV_8U 0/1 (before undistortion): the union of
  // mask_files, each read by read_mask.
  cv::Mat load_mask(int frame, int camera) const;

 protected:
  HumanSequence(std::string name, std::filesystem::path dir)
      : name_(std::move(name)), dir_(std::move(dir)) {}
  std::vector<Camera> cameras_;
  std::vector<std::string> camera_names_;

 private:
  std::string name_;
  std::filesystem::path dir_;
};

// What opening a person's folder needs beyond the folder.
struct OpenOptions {
  DataLayout layout = DataLayout::automatic;
  int person_id = -1;  // EasyMocap: which person of the SMPL files; -1: the only one
  // EasyMocap stores no vertices: they are computed with this model.
  std::shared_ptr<const body::SmplModel> smpl;
  CalibrationCheck calibration_check = CalibrationCheck::error;
};

// The layout a folder holds: annots.npy -> zju_mocap, intri.yml + extri.yml -> easymocap.
// Throws naming the folder and what was looked for when it holds neither (or both, with
// DataLayout::automatic).
DataLayout detect_layout(const std::filesystem::path& dir);
// Opens a person's folder in the layout `options` names (automatic: detect_layout, logged).
std::shared_ptr<HumanSequence> open_human(const std::filesystem::path& dir,
                                          const OpenOptions& options);

// A camera by name or index. `value` is a camera's name where one is called that, otherwise a
// decimal integer is a calibration index (data.reference_views, --reference-views); with
// `index_only` (a plain number in a split file) it is an index. Throws naming `where`, the value
// and the person's cameras.
int camera_index(const HumanSequence& human, const std::string& value, const std::string& where,
                 bool index_only = false);

// The `count` cameras most evenly spread around the body (METHOD 1.2, captures without a split):
// each camera's azimuth is the angle of its centre around the body's centre, in the plane of best
// fit through the camera centres; of all sets of `count` cameras the one whose largest angular gap
// between neighbours is smallest wins, ties to the smaller sum of squared gaps, then to the
// smaller indices. count 1: camera 0. Returned in increasing index order.
std::vector<int> spread_cameras(const HumanSequence& human, const torch::Tensor& body_vertices,
                                int count);

// Reads an image, refusing special files, unreadable and truncated (JPEG without its end marker)
// ones, naming the path.
cv::Mat read_image(const std::filesystem::path& path, int flags);
// A mask file as CV_8U, 255 where it marks the person: a non-zero value at any bit depth (8- or
// 16-bit, 0/1 or 0/255 alike), in any channel of a colour image, or in the alpha channel where
// one varies (an alpha-only cut-out). Throws naming the path as read_image does.
cv::Mat read_mask(const std::filesystem::path& path);
// Every value of `t` finite, else an error naming the file, `what` and the first offender.
void require_finite(const torch::Tensor& t, const std::filesystem::path& file,
                    const std::string& what);

// One view after METHOD 2.1: undistorted, resized by `ratio`, background black.
struct ViewImage {
  cv::Mat rgb;  // CV_32FC3, RGB in [0, 1]
  // CV_8U: 0 background, 1 person, 100 border band (target views only). With the band marked
  // before undistortion [parity], edge pixels hold bilinear blends of 0, 1 and 100.
  cv::Mat mask;
  Camera camera;  // K scaled by ratio (no half-pixel shift), T in metres
};

struct ViewOptions {
  double ratio = 0.5;
  bool border_band = false;  // target views: mark dilate5x5 - erode5x5 with 100
  const JitterParams* jitter = nullptr;
  // METHOD 2.1 step 6 [parity]: the band is marked on the distorted mask, which is then undistorted
  // (bilinear); false: marked on the undistorted mask (a clean 0/1/100 mask).
  bool band_before_undistort = true;
};
ViewImage load_view(const HumanSequence& human, int frame, int camera, const ViewOptions& options);

}  // namespace th::data
