#pragma once
// Options of transhuman-synth (configs/synth/default.yaml states the defaults).

#include <cstdint>
#include <string>
#include <vector>

#include "core/config_io.hpp"

namespace th::synth {

struct SynthPeopleConfig {
  // Folder names; training people first. CoreView_313/315 get the 21-camera layout with
  // original-style long file names, CoreView_396 the params/ + vertices/ folders (METHOD 1.1).
  std::vector<std::string> train{"CoreView_313", "CoreView_315", "CoreView_396", "CoreView_s04",
                                 "CoreView_s05", "CoreView_s06", "CoreView_s07"};
  std::vector<std::string> unseen{"CoreView_s08", "CoreView_s09", "CoreView_s10"};
  double shape_std = 1.0;  // standard deviation of the shape coefficients (clipped at 2.5 std)
};

struct SynthCameraConfig {
  int count = 23;       // cameras in the ring (the 21-camera people drop 20 and 21)
  double radius = 3.0;  // metres from the ring centre
  double radius_jitter = 0.08;
  double height = 1.25;  // camera height above the floor (metres), varied around the ring
  double height_spread = 0.3;
  double focal = 1.15;          // focal length in units of the image width
  double distortion = 1.0;      // scales the random lens distortion (0: none)
  double recalibration = 0.01;  // per-person jitter of the rig (metres), as a new calibration
};

struct SynthImageConfig {
  int width = 512;
  int height = 512;
  int supersample = 2;  // anti-aliasing: s x s samples per pixel
  int jpeg_quality = 75;
};

struct SynthNoiseConfig {
  bool enabled = true;     // published params/vertices = true + noise (a fitting error)
  double pose_std = 0.03;  // radians, per axis-angle component of joints 1..23
  double rh_std = 0.015;   // radians, global rotation
  double th_std = 0.01;    // metres, translation
  double shape_std = 0.0;  // shape coefficients
};

struct SynthSplitConfig {
  int train_frames = 40;   // frames [0, train_frames) of the training people are for training
  int pose_interval = 5;   // pose generalisation: later frames of the training people
  int test_interval = 10;  // identity / one-shot generalisation: the unseen people
  int fitting_interval = 10;
};

struct SynthConfig {
  // zju_mocap: annots.npy, new_params/, new_vertices/ (METHOD 1.1); easymocap: intri.yml,
  // extri.yml, images/, mask/, output/smpl/ (data/easymocap.hpp), the same people and pixels.
  std::string layout = "zju_mocap";
  int64_t seed = 1;
  int frames = 60;  // frames per person
  int threads = 2;  // render workers
  bool contact_sheet = true;
  SynthPeopleConfig people;
  SynthCameraConfig cameras;
  SynthImageConfig image;
  SynthNoiseConfig noise;
  SynthSplitConfig split;
};

template <class V>
void visit_fields(V& v, SynthPeopleConfig& c) {
  v("train", c.train);
  v("unseen", c.unseen);
  v("shape_std", c.shape_std);
}
template <class V>
void visit_fields(V& v, SynthCameraConfig& c) {
  v("count", c.count);
  v("radius", c.radius);
  v("radius_jitter", c.radius_jitter);
  v("height", c.height);
  v("height_spread", c.height_spread);
  v("focal", c.focal);
  v("distortion", c.distortion);
  v("recalibration", c.recalibration);
}
template <class V>
void visit_fields(V& v, SynthImageConfig& c) {
  v("width", c.width);
  v("height", c.height);
  v("supersample", c.supersample);
  v("jpeg_quality", c.jpeg_quality);
}
template <class V>
void visit_fields(V& v, SynthNoiseConfig& c) {
  v("enabled", c.enabled);
  v("pose_std", c.pose_std);
  v("rh_std", c.rh_std);
  v("th_std", c.th_std);
  v("shape_std", c.shape_std);
}
template <class V>
void visit_fields(V& v, SynthSplitConfig& c) {
  v("train_frames", c.train_frames);
  v("pose_interval", c.pose_interval);
  v("test_interval", c.test_interval);
  v("fitting_interval", c.fitting_interval);
}
template <class V>
void visit_fields(V& v, SynthConfig& c) {
  v("layout", c.layout);
  v("seed", c.seed);
  v("frames", c.frames);
  v("threads", c.threads);
  v("contact_sheet", c.contact_sheet);
  v("people", c.people);
  v("cameras", c.cameras);
  v("image", c.image);
  v("noise", c.noise);
  v("split", c.split);
}

// Refuses inconsistent values (th::Error naming the key).
void validate_section(const SynthConfig& c, const std::string& path);

}  // namespace th::synth
