#pragma once
// A trained model ready to be used outside the training loop (METHOD 7): the body model, a
// dataset setting (its people, fixed reference views and cameras) and the network with its
// weights. Prepares one frame of one person at a time and answers what free-viewpoint video
// and mesh extraction ask of it: an image from any pinhole camera, densities, colours.

#include <torch/types.h>

#include <filesystem>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "core/config.hpp"
#include "core/resources.hpp"
#include "data/dataset.hpp"
#include "model/frame_cache.hpp"
#include "model/inputs.hpp"
#include "model/transhuman.hpp"
#include "pipeline/pipeline.hpp"
#include "video/camera_path.hpp"

namespace th::inference {

// One frame of one person, prepared: the reference images and body of the frame (in
// `sample`, loaded as evaluation loads it), the network's inputs and its per-frame cache.
struct PreparedFrame {
  int human = 0;
  int frame = 0;
  data::Sample sample;
  model::FrameInputs inputs;
  model::FrameCache cache;
};

// A checkpoint file's identity: its absolute path, size and modification time.
std::string checkpoint_identity(const std::filesystem::path& checkpoint);

class Session {
 public:
  // Loads the body model, the setting config.eval.setting of config.data's split file (as
  // transhuman-eval does: fixed reference views), the network and `checkpoint` (ours or the
  // reference's). Throws th::Error naming what is missing.
  Session(const Config& config, const torch::Device& device,
          const std::filesystem::path& checkpoint);
  // A session over a network already in memory (evaluation's, or training's at a validation):
  // `model` as it is (weights, device, mode and products untouched) with `dataset`'s setting and
  // the body model's template `canonical`; `identity` stands for the checkpoint's identity
  // (checkpoint_id).
  Session(const Config& config, const torch::Device& device, model::TransHuman model,
          std::shared_ptr<const data::Dataset> dataset, const torch::Tensor& canonical,
          std::string identity);

  // Index of a person of the setting by folder name (empty: the setting's first). Throws
  // th::Error listing the setting's people.
  int find_human(const std::string& name) const;
  const data::HumanSequence& human(int index) const;
  // The frames of person `index` that the setting lists, in order.
  std::vector<int> setting_frames(int index) const;

  // Centre of the box of a frame's body (world, (3) float64): where the orbit looks.
  torch::Tensor body_center(int human, int frame) const;

  // Prepares frame `frame` (index into the person's annots) with the setting's reference
  // views; `view` is the camera whose intrinsics and image size the output camera takes (METHOD
  // 7: target view 3). Throws th::Error for an out-of-range index.
  PreparedFrame prepare(int human, int frame, int view) const;
  // Prepares the frame of a sample already loaded from the dataset above (its person,
  // frame and reference views).
  PreparedFrame prepare(data::Sample sample) const;

  // Dataset camera `view` of the prepared frame's person at the working resolution: K scaled
  // by data.ratio as the reader scales it, R, T (metres), float64.
  video::PathCamera dataset_camera(const PreparedFrame& frame, int view) const;

  // Renders `camera` at width x height as evaluation does (progressive rendering, culling,
  // chunks of render.chunk_points, no autograd): (H, W, 3) float32 CPU RGB in [0, 1], black
  // where no ray meets the frame's box.
  // Rays are made and rendered `band_pixels` pixels (whole rows) at a time.
  static constexpr int64_t kRenderBandPixels = int64_t{1} << 18;
  torch::Tensor render(const PreparedFrame& frame, const video::PathCamera& camera, int width,
                       int height, int64_t band_pixels = kRenderBandPixels) const;
  // What an interactive view needs beside rgb: depth (metres along the ray, 0 where no ray meets
  // the box) and accumulated opacity, (H, W) float32 each.
  struct ViewImages {
    torch::Tensor rgb, depth, acc;
  };
  // `samples` per ray (0: render.samples); `cancelled`, polled between bands of rows, ends the
  // render early (nullopt then).
  struct ViewControl {
    int samples = 0;
    std::function<bool()> cancelled;
    int64_t band_pixels = kRenderBandPixels;
  };
  std::optional<ViewImages> render_view(const PreparedFrame& frame, const video::PathCamera& camera,
                                        int width, int height, const ViewControl& control) const;
  // Dataset view `view` of frame `frame` rendered and scored exactly as transhuman-eval scores
  // it (PSNR over the rays of the body's box, SSIM on its crop; no LPIPS): what a viewer shows
  // beside the ground truth when it snaps to a dataset camera.
  pipeline::ViewResult evaluate_view(int human, int frame, int view) const;
  // Peak memory and samples of rendering `frames` frames like `frame` at width x height.
  resources::Estimate render_estimate(const PreparedFrame& frame, int width, int height,
                                      int frames) const;

  // Raw density sigma_raw of world points (N, 3): 0 for points farther than
  // render.cull_distance from the body (METHOD 7), the network elsewhere, in chunks of
  // render.chunk_points. (N) float32 CPU.
  torch::Tensor density(const PreparedFrame& frame, const torch::Tensor& pts) const;

  // Colour (N, 3) in [0, 1] of world points seen along ray directions dirs (N, 3), chunked.
  torch::Tensor color(const PreparedFrame& frame, const torch::Tensor& pts,
                      const torch::Tensor& dirs) const;

  // Raw density (N) and colours (K, N, 3) in [0, 1] of world points pts (N, 3) seen along each
  // of the K directions (K, 3), or K directions per point (K, N, 3) (baking, METHOD 7.1): the
  // network's per-point work is shared by the directions. sigma is 0 farther than
  // render.cull_distance from the body, as density() gives it; the colours are the network's
  // everywhere. In chunks; float32 CPU.
  struct DirectionalColors {
    torch::Tensor sigma, rgb;
  };
  DirectionalColors colors_along(const PreparedFrame& frame, const torch::Tensor& pts,
                                 const torch::Tensor& directions) const;

  // The checkpoint's path, size and modification time (checkpoint_identity), or the identity
  // the session was made with: which weights made a set of frames.
  std::string checkpoint_id() const;

  const Config& config() const { return config_; }
  const torch::Device& device() const { return device_; }
  const data::Dataset& dataset() const { return *dataset_; }

 private:
  Config config_;
  torch::Device device_;
  std::filesystem::path checkpoint_;
  std::string identity_;  // checkpoint_id()
  std::shared_ptr<const data::Dataset> dataset_;
  torch::Tensor canonical_;
  mutable std::unique_ptr<pipeline::Tokens> tokens_;
  mutable model::TransHuman model_{nullptr};  // evaluation only: the weights never change
};

}  // namespace th::inference
