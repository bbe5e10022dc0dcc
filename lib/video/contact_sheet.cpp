#include "video/contact_sheet.hpp"

#include <torch/torch.h>

#include <algorithm>
#include <cmath>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "core/error.hpp"

namespace th::video {

std::vector<int> evenly_spaced(int n, int count) {
  std::vector<int> out;
  if (n <= 0 || count <= 0) return out;
  if (count >= n || count == 1) {
    for (int i = 0; i < (count == 1 ? 1 : n); ++i) out.push_back(i);
    return out;
  }
  for (int k = 0; k < count; ++k)
    out.push_back(static_cast<int>(std::lround(double(k) * (n - 1) / (count - 1))));
  return out;
}

cv::Mat contact_sheet(const std::vector<cv::Mat>& images, const std::vector<std::string>& labels,
                      int columns, int thumb_width) {
  TORCH_CHECK(!images.empty(), "contact_sheet: no images");
  TORCH_CHECK(columns >= 1 && thumb_width >= 1,
              "contact_sheet: columns and thumb_width must be >= 1");
  const int gap = 4;
  std::vector<cv::Mat> thumbs;
  int cell_h = 1;
  for (const cv::Mat& image : images) {
    TORCH_CHECK(image.type() == CV_8UC3, "contact_sheet: images must be BGR CV_8UC3");
    const int h =
        std::max(1, static_cast<int>(std::lround(double(image.rows) * thumb_width / image.cols)));
    cv::Mat thumb;
    cv::resize(image, thumb, cv::Size(thumb_width, h), 0, 0, cv::INTER_AREA);
    thumbs.push_back(thumb);
    cell_h = std::max(cell_h, h);
  }
  const int n = static_cast<int>(thumbs.size());
  const int cols = std::min(columns, n), rows = (n + columns - 1) / columns;
  cv::Mat sheet(rows * cell_h + (rows + 1) * gap, cols * thumb_width + (cols + 1) * gap, CV_8UC3,
                cv::Scalar::all(0));
  for (int k = 0; k < n; ++k) {
    const int x = gap + (k % columns) * (thumb_width + gap);
    const int y = gap + (k / columns) * (cell_h + gap);
    thumbs[k].copyTo(sheet(cv::Rect(x, y, thumbs[k].cols, thumbs[k].rows)));
    if (k < static_cast<int>(labels.size()) && !labels[k].empty()) {
      // About 1/25 of the thumbnail wide per character, shrunk to fit in the cell.
      int base = 0;
      const cv::Size unit = cv::getTextSize(labels[k], cv::FONT_HERSHEY_SIMPLEX, 1.0, 1, &base);
      const double scale = std::min(thumb_width / 400.0 * 1.6, 0.9 * thumb_width / unit.width);
      const cv::Point at(x + 3, y + static_cast<int>(unit.height * scale) + 3);
      // Dark outline under white text: readable on any frame.
      cv::putText(sheet, labels[k], at, cv::FONT_HERSHEY_SIMPLEX, scale, cv::Scalar::all(0), 3,
                  cv::LINE_AA);
      cv::putText(sheet, labels[k], at, cv::FONT_HERSHEY_SIMPLEX, scale, cv::Scalar::all(255), 1,
                  cv::LINE_AA);
    }
  }
  return sheet;
}

cv::Mat contact_sheet(const std::vector<std::filesystem::path>& frames, int count, int columns,
                      int thumb_width) {
  std::vector<cv::Mat> images;
  std::vector<std::string> labels;
  for (int i : evenly_spaced(static_cast<int>(frames.size()), count)) {
    std::error_code ec;
    if (!std::filesystem::is_regular_file(frames[i], ec))
      fail("image '", frames[i].string(), "' for the contact sheet is missing");
    cv::Mat image = cv::imread(frames[i].string(), cv::IMREAD_COLOR);
    if (image.empty()) fail("cannot read image '", frames[i].string(), "' for the contact sheet");
    images.push_back(image);
    labels.push_back(frames[i].stem().string());
  }
  if (images.empty()) fail("contact sheet: no frames given");
  return contact_sheet(images, labels, columns, thumb_width);
}

}  // namespace th::video
