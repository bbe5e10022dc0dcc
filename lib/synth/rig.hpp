#pragma once
// The capture rig: a ring of calibrated cameras around the floor's origin (z up), as in the
// ZJU-MoCap studio, with slightly different calibrations per recording.

#include <torch/types.h>

#include <vector>

#include "synth/config.hpp"
#include "synth/random.hpp"

namespace th::synth {

struct CameraCalib {
  torch::Tensor K;  // (3, 3) float64, for the written image size
  torch::Tensor R;  // (3, 3) float64, world -> camera
  torch::Tensor T;  // (3, 1) float64, metres (annots.npy stores millimetres)
  torch::Tensor D;  // (5, 1) float64, OpenCV k1, k2, p1, p2, k3
};

// The studio's ring of `config.count` cameras looking at the centre, drawn from rng.
std::vector<CameraCalib> make_ring(const SynthCameraConfig& config, int width, int height,
                                   Rng& rng);

// One recording's calibration: the ring cameras `indices` (calibration order), each moved by
// about `config.recalibration` metres and re-aimed, as a fresh calibration would find them.
std::vector<CameraCalib> recalibrate(const std::vector<CameraCalib>& ring,
                                     const std::vector<int>& indices,
                                     const SynthCameraConfig& config, Rng& rng);

// Ring positions of CoreView_313/315's cameras: of 23, 0..18, 21, 22 (METHOD 1.1); of other
// ring sizes likewise all but the fourth- and third-last.
std::vector<int> cameras_21(int count);

}  // namespace th::synth
