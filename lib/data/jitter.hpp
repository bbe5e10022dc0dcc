#pragma once
// Colour jitter (METHOD 2.1): brightness, contrast, saturation and hue in random order, as
// torchvision's ColorJitter, with one set of parameters shared by the target and all reference
// views of a sample.

#include <array>
#include <opencv2/core.hpp>
#include <random>

#include "core/config.hpp"

namespace th::data {

struct JitterParams {
  double brightness = 1, contrast = 1, saturation = 1, hue = 0;
  std::array<int, 4> order{0, 1, 2, 3};  // 0 brightness, 1 contrast, 2 saturation, 3 hue
};

JitterParams sample_jitter(const JitterConfig& config, std::mt19937_64& rng);
// rgb: CV_32FC3 in [0, 1], modified in place (results clamped to [0, 1]).
void apply_jitter(cv::Mat& rgb, const JitterParams& params);

}  // namespace th::data
