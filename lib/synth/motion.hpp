#pragma once
// Motion of a synthetic person: a random script of activities (walking on a small circle,
// raising the arms, squatting, twirling, waving, kicking, idling), cross-faded into one
// sequence of SMPL parameters per frame.

#include <array>
#include <string>
#include <vector>

#include "synth/random.hpp"

namespace th::synth {

struct FrameParams {
  std::array<double, 72> poses{};  // axis-angle per joint; the root's is 0 (Rh holds it)
  std::array<double, 3> Rh{};      // world rotation (axis-angle): heading x (y up -> z up)
  std::array<double, 3> Th{};      // world translation (metres); z is set later for contact
};

struct Motion {
  std::vector<FrameParams> frames;
  std::string script;  // e.g. "walk 14, squat 12, twirl 16, ..." for the summary
};

// `frames` frames of motion drawn from rng.
Motion make_motion(int frames, Rng& rng);

}  // namespace th::synth
