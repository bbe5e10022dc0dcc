#include "pipeline/images.hpp"

#include <torch/torch.h>

#include <opencv2/imgproc.hpp>

namespace th::pipeline {

cv::Mat error_map(const torch::Tensor& pred, const torch::Tensor& gt, double full_scale) {
  const auto err =
      ((pred.detach().cpu().to(torch::kFloat32) - gt.detach().cpu().to(torch::kFloat32))
           .abs()
           .mean(2) /
       float(full_scale))
          .clamp(0, 1);
  const auto u8 = (err * 255.0f).to(torch::kUInt8).contiguous();
  cv::Mat gray(int(u8.size(0)), int(u8.size(1)), CV_8U, u8.data_ptr()), colour;
  cv::applyColorMap(gray, colour, cv::COLORMAP_JET);
  return colour;
}

cv::Mat panel(const std::vector<cv::Mat>& images, const std::vector<std::string>& captions) {
  TORCH_CHECK(!images.empty(), "panel: no images");
  const int h = images[0].rows, strip = 18;
  std::vector<cv::Mat> columns;
  for (size_t i = 0; i < images.size(); ++i) {
    cv::Mat img = images[i];
    if (img.rows != h)
      cv::resize(img, img, cv::Size(std::max(1, img.cols * h / img.rows), h), 0, 0, cv::INTER_AREA);
    cv::Mat col(h + strip, img.cols, CV_8UC3, cv::Scalar(30, 30, 30));
    img.copyTo(col(cv::Rect(0, strip, img.cols, h)));
    if (i < captions.size())
      cv::putText(col, captions[i], cv::Point(3, 13), cv::FONT_HERSHEY_SIMPLEX, 0.4,
                  cv::Scalar(235, 235, 235), 1, cv::LINE_AA);
    columns.push_back(col);
  }
  cv::Mat out;
  cv::hconcat(columns, out);
  return out;
}

}  // namespace th::pipeline
