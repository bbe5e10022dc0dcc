#include "data/jitter.hpp"

#include <algorithm>
#include <opencv2/imgproc.hpp>

namespace th::data {
namespace {

double uniform(std::mt19937_64& rng, const std::vector<double>& range) {
  return std::uniform_real_distribution<double>(range[0], range[1])(rng);
}

// ITU-R 601 luma, as torchvision's rgb_to_grayscale.
cv::Mat grayscale(const cv::Mat& rgb) {
  cv::Mat gray;
  cv::transform(rgb, gray, cv::Matx13f(0.299f, 0.587f, 0.114f));
  return gray;
}

void blend(cv::Mat& img, const cv::Mat& other3, double factor) {
  cv::addWeighted(img, factor, other3, 1.0 - factor, 0.0, img);
}

void shift_hue(cv::Mat& rgb, double hue) {
  cv::Mat hsv;
  cv::cvtColor(rgb, hsv, cv::COLOR_RGB2HSV);  // float: H in [0, 360)
  std::vector<cv::Mat> ch;
  cv::split(hsv, ch);
  ch[0] += hue * 360.0;
  cv::Mat h = ch[0];
  h.forEach<float>([](float& v, const int*) { v = std::fmod(std::fmod(v, 360.f) + 360.f, 360.f); });
  cv::merge(ch, hsv);
  cv::cvtColor(hsv, rgb, cv::COLOR_HSV2RGB);
}

}  // namespace

JitterParams sample_jitter(const JitterConfig& c, std::mt19937_64& rng) {
  JitterParams p;
  std::shuffle(p.order.begin(), p.order.end(), rng);
  p.brightness = uniform(rng, c.brightness);
  p.contrast = uniform(rng, c.contrast);
  p.saturation = uniform(rng, c.saturation);
  p.hue = uniform(rng, c.hue);
  return p;
}

void apply_jitter(cv::Mat& rgb, const JitterParams& p) {
  CV_Assert(rgb.type() == CV_32FC3);
  for (int op : p.order) {
    switch (op) {
      case 0:
        rgb *= p.brightness;
        break;
      case 1: {
        const double mean = cv::mean(grayscale(rgb))[0];
        blend(rgb, cv::Mat(rgb.size(), CV_32FC3, cv::Scalar::all(mean)), p.contrast);
        break;
      }
      case 2: {
        cv::Mat gray3;
        cv::cvtColor(grayscale(rgb), gray3, cv::COLOR_GRAY2RGB);
        blend(rgb, gray3, p.saturation);
        break;
      }
      case 3:
        shift_hue(rgb, p.hue);
        break;
    }
    cv::min(cv::max(rgb, 0.0), 1.0, rgb);
  }
}

}  // namespace th::data
