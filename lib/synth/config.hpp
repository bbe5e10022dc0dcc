#pragma once
// Options of transhuman-synth (configs/synth/default.yaml states the defaults).

#include <cstdint>
#include <string>
#include <vector>

#include "core/config_io.hpp"

namespace th::synth {

// One line per key with its type, default, accepted values and description (core/config_io.hpp).
#define TH_SYNTH_PEOPLE_KEYS(X)                                                                   \
  X(key, std::vector<std::string>, train,                                                         \
    (std::vector<std::string>{"CoreView_313", "CoreView_315", "CoreView_396", "CoreView_s04",     \
                              "CoreView_s05", "CoreView_s06", "CoreView_s07"}),                   \
    {},                                                                                           \
    "training people's folder names: CoreView_313/315 get 21 cameras and the original long file " \
    "names, CoreView_396 params/ and vertices/ folders (METHOD 1.1)")                             \
  X(key, std::vector<std::string>, unseen,                                                        \
    (std::vector<std::string>{"CoreView_s08", "CoreView_s09", "CoreView_s10"}), {},               \
    "the unseen people's folder names (identity and one-shot settings)")                          \
  X(key, double, shape_std, 1.0, config::at_least(0),                                             \
    "standard deviation of the shape coefficients (clipped at 2.5 of it)")
TH_CONFIG_SECTION(SynthPeopleConfig, TH_SYNTH_PEOPLE_KEYS)

#define TH_SYNTH_CAMERA_KEYS(X)                                                                  \
  X(key, int, count, 23, config::in(1, 99),                                                      \
    "cameras in the ring (the 21-camera people drop the 20th and 21st)")                         \
  X(key, double, radius, 3.0, config::above(0), "metres from the ring's centre")                 \
  X(key, double, radius_jitter, 0.08, config::at_least(0), "metres, per camera")                 \
  X(key, double, height, 1.25, {},                                                               \
    "camera height above the floor in metres, varied around the ring")                           \
  X(key, double, height_spread, 0.3, config::at_least(0), "metres, alternating around the ring") \
  X(key, double, focal, 1.15, config::above(0), "focal length in units of the image width")      \
  X(key, double, distortion, 1.0, config::at_least(0),                                           \
    "scale of the random lens distortion (0: pinhole)")                                          \
  X(key, double, recalibration, 0.01, config::at_least(0),                                       \
    "per-person jitter of the rig in metres, as a new calibration")
TH_CONFIG_SECTION(SynthCameraConfig, TH_SYNTH_CAMERA_KEYS)

#define TH_SYNTH_IMAGE_KEYS(X)                                                            \
  X(key, int, width, 512, config::in(16, 8192), "image width in pixels")                  \
  X(key, int, height, 512, config::in(16, 8192), "image height in pixels")                \
  X(key, int, supersample, 2, config::in(1, 4), "anti-aliasing: s x s samples per pixel") \
  X(key, int, jpeg_quality, 75, config::in(1, 100), "JPEG quality of the images")
TH_CONFIG_SECTION(SynthImageConfig, TH_SYNTH_IMAGE_KEYS)

#define TH_SYNTH_NOISE_KEYS(X)                                                       \
  X(key, bool, enabled, true, {},                                                    \
    "published params and vertices = the truth + noise (a fitting error)")           \
  X(key, double, pose_std, 0.03, config::at_least(0),                                \
    "radians, per axis-angle component of joints 1..23")                             \
  X(key, double, rh_std, 0.015, config::at_least(0), "radians, the global rotation") \
  X(key, double, th_std, 0.01, config::at_least(0), "metres, the translation")       \
  X(key, double, shape_std, 0.0, config::at_least(0), "the shape coefficients")
TH_CONFIG_SECTION(SynthNoiseConfig, TH_SYNTH_NOISE_KEYS)

#define TH_SYNTH_SPLIT_KEYS(X)                                                           \
  X(key, int, train_frames, 40, config::at_least(1),                                     \
    "frames [0, train_frames) of the training people are for training (at most frames)") \
  X(key, int, pose_interval, 5, config::at_least(1),                                     \
    "pose generalisation: every n-th later frame of the training people")                \
  X(key, int, test_interval, 10, config::at_least(1),                                    \
    "identity and one-shot: every n-th frame of the unseen people")                      \
  X(key, int, fitting_interval, 10, config::at_least(1), "fitting: every n-th frame")
TH_CONFIG_SECTION(SynthSplitConfig, TH_SYNTH_SPLIT_KEYS)

#define TH_SYNTH_KEYS(X)                                                                     \
  X(names, std::string, layout, "zju_mocap", config::names("zju_mocap", "easymocap"),        \
    "zju_mocap: annots.npy, new_params/, new_vertices/ (METHOD 1.1); easymocap: intri.yml, " \
    "extri.yml, images/, mask/, output/smpl/, the same people and pixels")                   \
  X(key, int64_t, seed, 1, {}, "random seed")                                                \
  X(key, int, frames, 60, config::at_least(1), "frames per person")                          \
  X(key, int, threads, 2, config::in(1, 4096), "render workers")                             \
  X(key, bool, contact_sheet, true, {}, "<out>/contact_sheet.png: people x (frames, views)") \
  X(section, SynthPeopleConfig, people, , , "who is generated")                              \
  X(section, SynthCameraConfig, cameras, , , "the camera ring")                              \
  X(section, SynthImageConfig, image, , , "the images")                                      \
  X(section, SynthNoiseConfig, noise, , , "the published fits' error")                       \
  X(section, SynthSplitConfig, split, , , "data_splits/synthetic.yaml is the split of the defaults")
TH_CONFIG_SECTION(SynthConfig, TH_SYNTH_KEYS)

// Refuses inconsistent values (th::Error naming the key).
void validate_section(const SynthConfig& c, const std::string& path);

}  // namespace th::synth
