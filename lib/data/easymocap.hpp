#pragma once
// EasyMocap's layout (METHOD 1.1), the one own multi-view captures come in after EasyMocap's
// calibration and multi-view SMPL fitting (docs/YOUR_CAPTURE.md). A person's folder holds:
//
//   intri.yml      OpenCV FileStorage: names (the cameras, strings or integers), K_<c> (3x3),
//                  dist_<c> (1x5 or 5x1; 1x4 or 4x1: k3 = 0). At most 1 MiB, nesting 64 deep
//   extri.yml      Rot_<c> (3x3) and/or R_<c> (Rodrigues 3x1), T_<c> (3x1, metres):
//                  world to camera X_c = R X + T
//   images/<c>/<frame>.jpg (or .png)       frames numbered from 0, zero-padded
//   mask/<c>/<frame>.png or masks/<c>/<frame>.png        non-zero: the person (read_mask)
//   output/smpl/<frame>.json or smpl/<frame>.json        a list of people, each
//                  {"id", "Rh": [[3]], "Th": [[3]], "poses": [[72]], "shapes": [[10]]}, ids
//                  distinct; at most 8 MiB, nesting 8 deep
//
// Vertices are not stored: they are LBS(poses, shapes) turned by Rh and moved by Th, computed
// with the project's SMPL model and rounded to float32, the precision ZJU-MoCap's vertex files
// hold, so a capture reads the same in either layout.

#include <filesystem>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "data/sequence.hpp"

namespace th::data {

class EasyMocapSequence final : public HumanSequence {
 public:
  // Reads intri.yml and extri.yml and lists images/. Throws th::Error naming the file and key.
  static std::shared_ptr<EasyMocapSequence> open(const std::filesystem::path& dir,
                                                 const OpenOptions& options);

  const char* layout() const override { return "easymocap"; }
  std::filesystem::path calibration_file() const override { return dir() / "extri.yml"; }
  int num_frames() const override { return int(frames_.size()); }
  std::filesystem::path image_path(int frame, int camera) const override;
  int frame_number(int frame) const override;
  BodyParams load_params(int frame) const override;
  torch::Tensor load_vertices(int frame) const override;
  // mask/ and masks/, whichever exist.
  std::vector<std::filesystem::path> mask_files(int frame, int camera) const override;

 private:
  EasyMocapSequence(std::string name, std::filesystem::path dir)
      : HumanSequence(std::move(name), std::move(dir)) {}
  void read_calibration(CalibrationCheck check);
  void list_images();
  void check_frame(int frame) const;

  struct Frame {
    int number = 0;
    std::string stem;                      // the file name without extension, e.g. 000012
    std::vector<std::string> image_names;  // per camera, e.g. 000012.jpg
  };
  std::vector<Frame> frames_;
  int person_id_ = -1;
  std::shared_ptr<const body::SmplModel> smpl_;
};

}  // namespace th::data
