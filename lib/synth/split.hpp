#pragma once
// The split file of a synthetic dataset: the paper's protocols (METHOD 1.2) over the generated
// people and frames. data_splits/synthetic.yaml is this file for configs/synth/default.yaml;
// every generated dataset also carries its own copy as <out>/split.yaml.
//
// The schema is the one of every file in data_splits/ (documented in data_splits/zju_mocap.yaml
// and at the top of the file written here): settings -> {reference_views: [..] | random,
// num_reference_views, target_views: [..] | all, humans: [{name, begin, ni, interval}]}.

#include <string>

#include "synth/config.hpp"

namespace th::synth {

std::string split_yaml(const SynthConfig& config);

}  // namespace th::synth
