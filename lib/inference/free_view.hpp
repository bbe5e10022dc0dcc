#pragma once
// Free-viewpoint video (METHOD 7): a trained model renders one person from a moving virtual
// camera, for one frame or a frame range (the person moving while the camera orbits), with
// the setting's fixed reference views. Cameras: the orbit of METHOD 7, a camera path file
// (video/camera_path.hpp), or one dataset camera. Output: PNG frames, an mp4 at 30 fps, the
// camera path as a file, a contact sheet. Resumable: frames already written are skipped, as
// long as the request is the same one: person, frames, cameras, size, the checkpoint, and every
// setting that changes pixels (precision, eval.setting, the data, model and render keys;
// request.yaml in the output folder says which).

#include <filesystem>
#include <functional>
#include <string>
#include <utility>
#include <vector>

#include "inference/session.hpp"

namespace th::dist {
class Communicator;
}

namespace th::inference {

struct VideoRequest {
  std::string human;        // folder name; empty: the setting's first person
  std::vector<int> frames;  // body frames (annots indices); empty: the setting's first
  enum class Cameras { Orbit, PathFile, Dataset } cameras = Cameras::Orbit;
  int orbit_views = 0;              // orbit cameras; 0: 36, or one per frame of a frame range
  std::filesystem::path path_file;  // Cameras::PathFile
  std::string camera;               // Cameras::Dataset: the camera's name or calibration index
  int view = 3;                     // the orbit's intrinsics and image size (METHOD 7: view 3)
  int width = 0, height = 0;        // output size; 0: the view's image at data.ratio (K scaled)
  bool force = false;               // discard frames of an earlier, different request
  int contact_sheet_frames = 12;    // 0: no contact sheet
  // Another renderer in place of Session::render (a baked one, METHOD 7.1): (H, W, 3) float32
  // RGB in [0, 1]. `renderer_id` says what it is, `renderer_keys` (key, value) what it renders
  // from (a bake's voxel, brick and identity); request.yaml records both, so frames of one
  // renderer, or of one bake, are never resumed by another.
  std::function<torch::Tensor(const PreparedFrame&, const video::PathCamera&, int, int)> renderer;
  std::string renderer_id;
  std::vector<std::pair<std::string, std::string>> renderer_keys;
};

struct VideoSummary {
  int frames = 0;    // video length
  int rendered = 0;  // rendered by this run
  int skipped = 0;   // already there (resumed)
  double seconds_per_frame = 0;
  std::filesystem::path frames_dir;
  bool video_written = false;
  std::string video_message;
  std::filesystem::path contact_sheet;  // empty when not made
};

// A request resolved and checked against the data: everything render_video needs before it
// writes anything (also what `transhuman-render --dry-run` checks).
struct VideoPlan {
  int human = 0;  // the session's person index
  std::string human_name;
  std::vector<int> frames;               // body frames, cycled over the video
  int base_view = 0;                     // the dataset camera the output image is modelled on
  int width = 0, height = 0, count = 0;  // output size and video length
  std::vector<video::PathCamera> shots;  // one camera per video frame
  PreparedFrame prepared;                // the first body frame, ready to render
};

// Resolves `request` (see render_video for what is refused) and checks the memory it needs
// against max_memory_gb.
VideoPlan plan_video(const Session& session, const VideoRequest& request);

// Video frame k shows body frame frames[k % F] from camera cameras[k % C]; the video has
// max(F, C) frames. The orbit looks at the centre of each frame's body box. Throws th::Error
// for a bad request (unknown person, frame or camera out of range, unreadable path file, an
// output folder holding another request's frames without `force`, naming what differs; with
// `force` those frames are removed and rendered again).
//
// With `comm` (several ranks), the frames still to render are split over the ranks; rank 0
// (whose `out_dir` is the output folder: the others pass an empty one and write nothing)
// receives every frame and writes what one process writes: frames, video, contact sheet.
VideoSummary render_video(const Session& session, const VideoRequest& request,
                          const std::filesystem::path& out_dir, dist::Communicator* comm = nullptr);

// The most frames (and cameras) one video may have: an hour at 30 fps.
constexpr int64_t kMaxVideoFrames = 108000;

// "12" -> {12}; "0:60" -> 0..59; "0:60:5" -> 0, 5, ..., 55 (end exclusive, as Python's
// range). Throws th::Error quoting the text when it is malformed, empty, negative or longer
// than kMaxVideoFrames.
std::vector<int> parse_frame_range(const std::string& text);

// K for an image resized by sx along x and sy along y: rows 0 and 1 scaled, without a
// half-pixel shift, as the dataset reader scales K by data.ratio (float64 (3, 3)).
torch::Tensor scale_intrinsics(const torch::Tensor& K, double sx, double sy);

}  // namespace th::inference
