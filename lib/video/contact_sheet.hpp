#pragma once
// A contact sheet: a grid of thumbnails of video frames (or mesh previews), labelled, for
// looking at a whole video in one PNG (in the run folder).

#include <filesystem>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

namespace th::video {

// `count` indices spread evenly over 0..n-1, first and last included (all of them if
// count >= n): evenly_spaced(36, 4) = {0, 12, 23, 35}.
std::vector<int> evenly_spaced(int n, int count);

// images: BGR CV_8UC3 (any sizes); each is scaled to thumb_width wide (aspect kept, cells as tall
// as the tallest thumbnail), laid out `columns` per row on a black background with 4 px gaps,
// labels drawn in each cell's corner (empty: none). Returns BGR CV_8UC3.
cv::Mat contact_sheet(const std::vector<cv::Mat>& images, const std::vector<std::string>& labels,
                      int columns, int thumb_width);

// Reads `count` evenly spaced files of `frames` and lays them out as above, labelled with their
// file names. Throws th::Error naming a file that cannot be read.
cv::Mat contact_sheet(const std::vector<std::filesystem::path>& frames, int count, int columns,
                      int thumb_width);

}  // namespace th::video
