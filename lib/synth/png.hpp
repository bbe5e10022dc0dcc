#pragma once
// A minimal PNG encoder for 8-bit single-channel masks. OpenCV's writer tries every PNG row
// filter on every row; masks are long runs of one value, for which no filter plus run-length
// deflate is both smaller and faster.

#include <opencv2/core.hpp>
#include <string>

namespace th::synth {

// image: CV_8UC1. Returns the bytes of a greyscale PNG that cv::imread reads back unchanged.
std::string encode_mask_png(const cv::Mat& image);

}  // namespace th::synth
