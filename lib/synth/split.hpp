#pragma once
// The split file of a synthetic dataset: the paper's protocols (SPEC 1.2) over the generated
// people and frames. data_splits/synthetic.yaml is this file for configs/synth/default.yaml;
// every generated dataset also carries its own copy as <out>/split.yaml.
//
// Schema (also documented at the top of the file):
//   dataset: synthetic
//   settings:
//     <setting>:                     training | pose | identity | one_shot | fitting
//       humans:                      list of {human, begin, ni, interval}; the frames of a
//                                    human are ims[begin : begin + ni][::interval]
//       reference_views: [...]       calibration indices of the input views; [] = random
//       num_reference_views: n       number of random reference views when the list is empty
//       target_views: [...]          calibration indices of the views to render; [] = all

#include <string>

#include "synth/config.hpp"

namespace th::synth {

std::string split_yaml(const SynthConfig& config);

}  // namespace th::synth
