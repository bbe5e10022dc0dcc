#pragma once
// The dataset object: samples of a split setting, each a target view with its rays and the
// reference views and body of the same frame (METHOD 1.2, 2, 5), plus background prefetching.

#include <torch/types.h>

#include <condition_variable>
#include <cstdint>
#include <deque>
#include <exception>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "core/config.hpp"
#include "data/sequence.hpp"
#include "data/split.hpp"

namespace th::body {
struct SmplModel;
}

namespace th::data {

// The body of one frame (METHOD 2.2, 2.3), float32.
struct FrameBody {
  torch::Tensor vertices;       // (Nv, 3) world
  torch::Tensor smpl_vertices;  // (Nv, 3) SMPL frame: Rh^T (x - Th)
  torch::Tensor Rh;             // (3, 3) rotation matrix
  torch::Tensor Th;             // (3)
  torch::Tensor A;              // (Nv, 3, 3) blended canonical -> posed rotations
  torch::Tensor bounds;         // (2, 3) world box, z padded
};

struct Sample {
  std::string human;
  int frame = 0;  // index into annots' ims
  int target_view = 0;
  std::vector<int> reference_views;

  torch::Tensor ref_images;  // (V, 3, H, W) float32 [0, 1], background black
  torch::Tensor ref_K;       // (V, 3, 3) float32, working resolution
  torch::Tensor ref_R;       // (V, 3, 3)
  torch::Tensor ref_T;       // (V, 3, 1) metres
  torch::Tensor visibility;  // (V, Nv) bool
  FrameBody body;

  torch::Tensor target_image;  // (H, W, 3) float32
  torch::Tensor target_mask;   // (H, W) uint8: 0, 1, 100 border band
  torch::Tensor K, R, T;       // target camera
  torch::Tensor box_mask;      // (H, W) bool: pixels whose ray hits the box (valid rays)

  // Rays to render, float32: origins, unnormalised directions, near/far, target colour, and the
  // flat pixel index (y * W + x) of each.
  torch::Tensor ray_o, ray_d, near, far, ray_rgb, ray_pixel;
  // Training patches: target colours (P, 3, S, S) (0 outside the image) and, per ray, its flat
  // position in that tensor's (P, S, S) grid.
  torch::Tensor patch_rgb, ray_patch_index;
};

class Dataset {
 public:
  enum class Mode { Train, Test };
  // Reads the split setting (or, with data.split_file empty, takes every person under data.root)
  // and opens every human it names (calibration and file lists only). The body model supplies
  // faces and LBS. Throws th::Error naming the missing folder or file.
  Dataset(const DataConfig& config, const std::string& setting, Mode mode,
          std::shared_ptr<const body::SmplModel> smpl);

  struct Item {
    int human;  // index into humans()
    int frame;
    int target_view;
  };
  size_t size() const { return items_.size(); }
  // Fails when a person has no target view (every camera a reference, without a split): what
  // evaluation needs and rendering new views does not.
  void require_targets() const;
  const Item& item(size_t index) const { return items_.at(index); }
  const std::vector<std::shared_ptr<HumanSequence>>& humans() const { return humans_; }
  const SplitSetting& setting() const { return setting_; }
  // The fixed reference cameras of human `human` (empty with random references).
  const std::vector<int>& reference_views(int human) const;
  // The frames the setting lists for human `human` (index into humans()), target views or not.
  const std::vector<int>& frames(int human) const;
  const body::SmplModel& smpl() const { return *smpl_; }
  Mode mode() const { return mode_; }

  // Loads sample `index`. Everything random (reference views, jitter, patches) is drawn from
  // `seed`, so a sample is reproducible and independent of the loading thread.
  Sample load(size_t index, uint64_t seed) const;
  // Loads any (human, frame, target view) of the setting's humans the same way, also frames
  // and views the setting does not list (free-viewpoint rendering of a whole sequence).
  // Throws th::Error naming the human and the valid range for an index out of range.
  Sample load_item(const Item& item, uint64_t seed) const;
  // The body of a frame (LBS + vertices file).
  FrameBody load_body(const HumanSequence& human, int frame) const;

 private:
  DataConfig config_;
  SplitSetting setting_;
  Mode mode_;
  std::shared_ptr<const body::SmplModel> smpl_;
  std::vector<std::shared_ptr<HumanSequence>> humans_;
  struct Views {
    std::vector<int> references, targets, frames;
  };
  std::vector<Views> views_;  // per human
  std::vector<Item> items_;
  std::string no_targets_;  // why a person has no target view, or ""
};

// The SMPL model a data config names (data.smpl_model, default <root>/smpl_model.npz).
std::shared_ptr<const body::SmplModel> load_body_model(const DataConfig& config);

// Loads samples in the background: `workers` threads fill a window of `depth` samples ahead of
// the consumer; next() returns them in `order`. An error while loading is rethrown by next()
// for the sample it concerns. workers == 0 loads synchronously in next().
class Prefetcher {
 public:
  Prefetcher(std::shared_ptr<const Dataset> dataset, std::vector<size_t> order,
             std::vector<uint64_t> seeds, int workers, int depth);
  ~Prefetcher();
  Prefetcher(const Prefetcher&) = delete;
  Prefetcher& operator=(const Prefetcher&) = delete;

  bool done() const { return next_ >= order_.size(); }
  Sample next();
  // Seconds next() spent waiting for a sample (the trainer's time lost to loading).
  double wait_seconds() const { return wait_seconds_; }

 private:
  void work();

  std::shared_ptr<const Dataset> dataset_;
  std::vector<size_t> order_;
  std::vector<uint64_t> seeds_;
  int depth_;
  size_t next_ = 0;     // next position the consumer takes
  size_t claimed_ = 0;  // next position a worker claims
  bool stop_ = false;
  double wait_seconds_ = 0;
  std::mutex mutex_;
  std::condition_variable cv_;
  std::map<size_t, Sample> ready_;
  std::map<size_t, std::exception_ptr> errors_;
  std::vector<std::thread> threads_;
};

}  // namespace th::data
