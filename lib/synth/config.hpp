#pragma once
// Options of transhuman-synth (configs/synth/default.yaml states the defaults).

#include <cstdint>
#include <string>
#include <vector>

#include "core/config_io.hpp"

namespace th::synth {

// Each field's type and default; its key, accepted values and description are in the section's
// visit_fields below, written once (core/config_io.hpp).
struct SynthPeopleConfig {
  std::vector<std::string> train{"CoreView_313", "CoreView_315", "CoreView_396", "CoreView_s04",
                                 "CoreView_s05", "CoreView_s06", "CoreView_s07"};
  std::vector<std::string> unseen{"CoreView_s08", "CoreView_s09", "CoreView_s10"};
  double shape_std = 1.0;
};

struct SynthCameraConfig {
  int count = 23;
  double radius = 3.0;
  double radius_jitter = 0.08;
  double height = 1.25;
  double height_spread = 0.3;
  double focal = 1.15;
  double distortion = 1.0;
  double recalibration = 0.01;
};

struct SynthImageConfig {
  int width = 512;
  int height = 512;
  int supersample = 2;
  int jpeg_quality = 75;
};

struct SynthNoiseConfig {
  bool enabled = true;
  double pose_std = 0.03;
  double rh_std = 0.015;
  double th_std = 0.01;
  double shape_std = 0.0;
};

struct SynthSplitConfig {
  int train_frames = 40;
  int pose_interval = 5;
  int test_interval = 10;
  int fitting_interval = 10;
};

struct SynthConfig {
  std::string layout = "zju_mocap";
  int64_t seed = 1;
  int frames = 60;
  int threads = 2;
  bool contact_sheet = true;
  SynthPeopleConfig people;
  SynthCameraConfig cameras;
  SynthImageConfig image;
  SynthNoiseConfig noise;
  SynthSplitConfig split;
};

template <class V>
void visit_fields(V& v, SynthPeopleConfig& c) {
  v("train", c.train,
    "training people's folder names: CoreView_313/315 get 21 cameras and the original long "
    "file names, CoreView_396 params/ and vertices/ folders (METHOD 1.1)");
  v("unseen", c.unseen, "the unseen people's folder names (identity and one-shot settings)");
  v("shape_std", c.shape_std, config::at_least(0),
    "standard deviation of the shape coefficients (clipped at 2.5 of it)");
}
template <class V>
void visit_fields(V& v, SynthCameraConfig& c) {
  v("count", c.count, config::in(1, 99),
    "cameras in the ring (the 21-camera people drop the 20th and 21st)");
  v("radius", c.radius, config::above(0), "metres from the ring's centre");
  v("radius_jitter", c.radius_jitter, config::at_least(0), "metres, per camera");
  v("height", c.height, "camera height above the floor in metres, varied around the ring");
  v("height_spread", c.height_spread, config::at_least(0), "metres, alternating around the ring");
  v("focal", c.focal, config::above(0), "focal length in units of the image width");
  v("distortion", c.distortion, config::at_least(0),
    "scale of the random lens distortion (0: pinhole)");
  v("recalibration", c.recalibration, config::at_least(0),
    "per-person jitter of the rig in metres, as a new calibration");
}
template <class V>
void visit_fields(V& v, SynthImageConfig& c) {
  v("width", c.width, config::in(16, 8192), "image width in pixels");
  v("height", c.height, config::in(16, 8192), "image height in pixels");
  v("supersample", c.supersample, config::in(1, 4), "anti-aliasing: s x s samples per pixel");
  v("jpeg_quality", c.jpeg_quality, config::in(1, 100), "JPEG quality of the images");
}
template <class V>
void visit_fields(V& v, SynthNoiseConfig& c) {
  v("enabled", c.enabled, "published params and vertices = the truth + noise (a fitting error)");
  v("pose_std", c.pose_std, config::at_least(0),
    "radians, per axis-angle component of joints 1..23");
  v("rh_std", c.rh_std, config::at_least(0), "radians, the global rotation");
  v("th_std", c.th_std, config::at_least(0), "metres, the translation");
  v("shape_std", c.shape_std, config::at_least(0), "the shape coefficients");
}
template <class V>
void visit_fields(V& v, SynthSplitConfig& c) {
  v("train_frames", c.train_frames, config::at_least(1),
    "frames [0, train_frames) of the training people are for training (at most frames)");
  v("pose_interval", c.pose_interval, config::at_least(1),
    "pose generalisation: every n-th later frame of the training people");
  v("test_interval", c.test_interval, config::at_least(1),
    "identity and one-shot: every n-th frame of the unseen people");
  v("fitting_interval", c.fitting_interval, config::at_least(1), "fitting: every n-th frame");
}
template <class V>
void visit_fields(V& v, SynthConfig& c) {
  v.choice("layout", c.layout, {"zju_mocap", "easymocap"},
           "zju_mocap: annots.npy, new_params/, new_vertices/ (METHOD 1.1); easymocap: intri.yml, "
           "extri.yml, images/, mask/, output/smpl/, the same people and pixels");
  v("seed", c.seed, "random seed");
  v("frames", c.frames, config::at_least(1), "frames per person");
  v("threads", c.threads, config::in(1, 4096), "render workers");
  v("contact_sheet", c.contact_sheet, "<out>/contact_sheet.png: people x (frames, views)");
  v("people", c.people, "who is generated");
  v("cameras", c.cameras, "the camera ring");
  v("image", c.image, "the images");
  v("noise", c.noise, "the published fits' error");
  v("split", c.split, "data_splits/synthetic.yaml is the split of the defaults");
}

// Refuses inconsistent values (th::Error naming the key).
void validate_section(const SynthConfig& c, const std::string& path);

}  // namespace th::synth
