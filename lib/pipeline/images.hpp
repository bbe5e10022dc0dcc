#pragma once
// Images for people to look at: validation renders, evaluation panels (prediction, ground
// truth, inputs, error map side by side). Conversion and PNG writing: video/frame_writer.hpp.

#include <torch/types.h>

#include <filesystem>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

namespace th::pipeline {

// Per-pixel mean absolute error of two (H, W, 3) images, as a colour map (0 -> dark blue,
// >= `full_scale` -> red).
cv::Mat error_map(const torch::Tensor& pred, const torch::Tensor& gt, double full_scale = 0.25);
// Images of equal height side by side (others are scaled to the first's height), each with a
// caption strip on top.
cv::Mat panel(const std::vector<cv::Mat>& images, const std::vector<std::string>& captions);
}  // namespace th::pipeline
