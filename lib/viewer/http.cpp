#include "viewer/http.hpp"

#include <torch/torch.h>

#include <algorithm>
#include <cmath>
#include <opencv2/imgcodecs.hpp>
#include <sstream>
#include <vector>

namespace th::viewer {

std::string param(const httplib::Request& req, const std::string& name) {
  if (!req.has_param(name.c_str())) throw BadRequest{"missing parameter '" + name + "'"};
  return req.get_param_value(name.c_str());
}

int int_param(const httplib::Request& req, const std::string& name, int lo, int hi) {
  const std::string text = param(req, name);
  size_t used = 0;
  long long v = 0;
  try {
    v = std::stoll(text, &used);
  } catch (const std::exception&) {
    used = 0;
  }
  if (text.empty() || used != text.size())
    throw BadRequest{"'" + name + "' = '" + text + "' is not an integer"};
  if (v < lo || v > hi)
    throw BadRequest{"'" + name + "' = " + text + " must be in [" + std::to_string(lo) + ", " +
                     std::to_string(hi) + "]"};
  return int(v);
}

double number(const std::string& name, const std::string& text) {
  size_t used = 0;
  double v = NAN;
  try {
    v = std::stod(text, &used);
  } catch (const std::exception&) {
    used = 0;
  }
  if (text.empty() || used != text.size() || !std::isfinite(v))
    throw BadRequest{"'" + name + "' holds '" + text + "', not a finite number"};
  return v;
}

torch::Tensor vec3(const httplib::Request& req, const std::string& name, double max_abs) {
  const std::string text = param(req, name);
  std::vector<double> v;
  std::stringstream ss(text);
  for (std::string part; std::getline(ss, part, ',');) v.push_back(number(name, part));
  if (v.size() != 3)
    throw BadRequest{"'" + name + "' = '" + text + "' must be three numbers x,y,z"};
  for (double x : v)
    if (std::abs(x) > max_abs)
      throw BadRequest{"'" + name + "' = '" + text + "' is farther than " +
                       std::to_string(int(max_abs)) + " from the origin"};
  return torch::tensor(v, torch::kFloat64);
}

video::PathCamera look_camera(const torch::Tensor& eye, const torch::Tensor& forward,
                              const torch::Tensor& up, double fovy, int width, int height) {
  if (forward.norm().item<double>() < 1e-9) throw BadRequest{"'forward' must not be zero"};
  const auto f = forward / forward.norm();
  auto right = torch::cross(f, up, 0);
  if (right.norm().item<double>() < 1e-6 * std::max(1.0, up.norm().item<double>()))
    throw BadRequest{"'up' must not be zero or parallel to 'forward'"};
  right = right / right.norm();
  const auto down = torch::cross(f, right, 0);
  const auto R = torch::stack({right, down, f});
  const auto T = -torch::mv(R, eye).reshape({3, 1});
  const double focal = 0.5 * height / std::tan(0.5 * fovy * M_PI / 180.0);
  const auto K = torch::tensor({focal, 0.0, 0.5 * width, 0.0, focal, 0.5 * height, 0.0, 0.0, 1.0},
                               torch::kFloat64)
                     .reshape({3, 3});
  return {K, R, T};
}

std::string body(const Json& answer) {
  return answer.dump(-1, ' ', false, Json::error_handler_t::replace);
}

Json vec3_json(const torch::Tensor& v) {
  const auto c = v.to(torch::kFloat64).contiguous();
  return Json::array({c[0].item<double>(), c[1].item<double>(), c[2].item<double>()});
}

std::string png(const torch::Tensor& image, bool jpeg) {
  const auto values = image.to(torch::kFloat32).contiguous();
  const int h = int(values.size(0)), w = int(values.size(1)), c = values.dim() == 3 ? 3 : 1;
  cv::Mat out(h, w, c == 3 ? CV_8UC3 : CV_8UC1);
  const float* in = values.data_ptr<float>();
  uint8_t* o = out.ptr<uint8_t>();
  const int64_t pixels = int64_t(h) * w;
  // One pass that also turns RGB into OpenCV's BGR.
  for (int64_t p = 0; p < pixels; ++p)
    for (int k = 0; k < c; ++k) {
      const float x = in[p * c + (c - 1 - k)] * 255.f;
      o[p * c + k] = x > 0 ? uint8_t(std::nearbyint(std::min(x, 255.f))) : 0;
    }
  std::vector<uchar> bytes;
  if (jpeg)
    cv::imencode(".jpg", out, bytes, {cv::IMWRITE_JPEG_QUALITY, 90});
  else
    cv::imencode(".png", out, bytes);
  return std::string(bytes.begin(), bytes.end());
}

torch::Tensor display(const torch::Tensor& rgb, const torch::Tensor& depth_in,
                      const torch::Tensor& acc, const std::string& mode) {
  if (mode == "rgb") return rgb;
  if (mode == "acc") return acc;
  const auto valid = acc > 1e-3;
  auto depth = depth_in.clone();
  if (valid.any().item<bool>()) {
    const auto d = depth.index({valid});
    const double lo = d.min().item<double>(), hi = d.max().item<double>();
    depth = torch::where(valid, 1.0 - (depth - lo) / std::max(hi - lo, 1e-6) * 0.8,
                         torch::zeros_like(depth));
  }
  return depth;
}

}  // namespace th::viewer
