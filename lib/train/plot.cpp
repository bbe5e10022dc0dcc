#include "train/plot.hpp"

#include <algorithm>
#include <cmath>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <opencv2/imgproc.hpp>
#include <set>
#include <string>
#include <vector>

#include "video/frame_writer.hpp"

namespace th::train {
namespace {

// The numeric fields of one metrics.jsonl record (none for a line that is not a JSON object:
// one cut short when a run was killed).
std::map<std::string, double> numbers(const std::string& line) {
  std::map<std::string, double> out;
  const auto row = nlohmann::json::parse(line, nullptr, /*allow_exceptions=*/false);
  if (!row.is_object()) return out;
  for (const auto& field : row.items())
    if (field.value().is_number()) out[field.key()] = field.value().get<double>();
  return out;
}

struct Series {
  std::vector<double> x, y;
};

void draw_panel(cv::Mat& img, cv::Rect area,
                const std::vector<std::pair<Series, cv::Scalar>>& lines, const std::string& title) {
  cv::rectangle(img, area, cv::Scalar(200, 200, 200));
  double x0 = 1e300, x1 = -1e300, y0 = 1e300, y1 = -1e300;
  for (const auto& [s, c] : lines)
    for (size_t i = 0; i < s.x.size(); ++i) {
      x0 = std::min(x0, s.x[i]), x1 = std::max(x1, s.x[i]);
      y0 = std::min(y0, s.y[i]), y1 = std::max(y1, s.y[i]);
    }
  if (x1 <= x0) x1 = x0 + 1;
  if (y1 <= y0) y1 = y0 + 1e-6;
  auto px = [&](double x, double y) {
    return cv::Point(area.x + int((x - x0) / (x1 - x0) * (area.width - 1)),
                     area.y + area.height - 1 - int((y - y0) / (y1 - y0) * (area.height - 1)));
  };
  for (const auto& [s, c] : lines) {
    std::vector<cv::Point> pts;
    for (size_t i = 0; i < s.x.size(); ++i) pts.push_back(px(s.x[i], s.y[i]));
    if (pts.size() == 1) cv::circle(img, pts[0], 3, c, cv::FILLED);
    cv::polylines(img, pts, false, c, 2, cv::LINE_AA);
    for (const auto& p : pts)
      if (s.x.size() < 40) cv::circle(img, p, 3, c, cv::FILLED, cv::LINE_AA);
  }
  char buf[64];
  cv::putText(img, title, cv::Point(area.x + 4, area.y - 8), cv::FONT_HERSHEY_SIMPLEX, 0.5,
              cv::Scalar(20, 20, 20), 1, cv::LINE_AA);
  std::snprintf(buf, sizeof buf, "%.4g", y1);
  cv::putText(img, buf, cv::Point(area.x - 58, area.y + 10), cv::FONT_HERSHEY_SIMPLEX, 0.4,
              cv::Scalar(60, 60, 60), 1, cv::LINE_AA);
  std::snprintf(buf, sizeof buf, "%.4g", y0);
  cv::putText(img, buf, cv::Point(area.x - 58, area.y + area.height), cv::FONT_HERSHEY_SIMPLEX, 0.4,
              cv::Scalar(60, 60, 60), 1, cv::LINE_AA);
  std::snprintf(buf, sizeof buf, "step %.0f", x0);
  cv::putText(img, buf, cv::Point(area.x, area.y + area.height + 16), cv::FONT_HERSHEY_SIMPLEX, 0.4,
              cv::Scalar(60, 60, 60), 1, cv::LINE_AA);
  std::snprintf(buf, sizeof buf, "step %.0f", x1);
  cv::putText(img, buf, cv::Point(area.x + area.width - 70, area.y + area.height + 16),
              cv::FONT_HERSHEY_SIMPLEX, 0.4, cv::Scalar(60, 60, 60), 1, cv::LINE_AA);
}

}  // namespace

bool plot_training_curve(const std::filesystem::path& metrics_jsonl,
                         const std::filesystem::path& png) {
  std::ifstream in(metrics_jsonl);
  Series loss, psnr, val;
  std::set<std::string> renderers;  // of the validation points
  for (std::string line; std::getline(in, line);) {
    const auto n = numbers(line);
    if (!n.count("step")) continue;
    const double step = n.at("step");
    if (n.count("loss"))
      loss.x.push_back(step), loss.y.push_back(std::log10(std::max(n.at("loss"), 1e-8)));
    if (n.count("psnr")) psnr.x.push_back(step), psnr.y.push_back(n.at("psnr"));
    if (n.count("val_psnr")) {
      val.x.push_back(step), val.y.push_back(n.at("val_psnr"));
      // "val_renderer": "baked 2 cm" (lines written before it was recorded: exact)
      const std::string key = "\"val_renderer\": \"";
      const size_t at = line.find(key);
      const size_t end = at == std::string::npos ? at : line.find('"', at + key.size());
      renderers.insert(end == std::string::npos
                           ? std::string("exact")
                           : line.substr(at + key.size(), end - at - key.size()));
    }
  }
  std::string renderer;
  for (const auto& r : renderers) renderer += (renderer.empty() ? "" : " + ") + r;
  if (loss.x.size() < 2) return false;
  cv::Mat img(360, 960, CV_8UC3, cv::Scalar(255, 255, 255));
  draw_panel(img, cv::Rect(70, 30, 380, 290), {{loss, cv::Scalar(180, 80, 30)}},
             "training loss (log10)");
  std::vector<std::pair<Series, cv::Scalar>> right{{psnr, cv::Scalar(40, 140, 40)}};
  if (!val.x.empty()) right.push_back({val, cv::Scalar(30, 30, 200)});
  draw_panel(img, cv::Rect(560, 30, 380, 290), right,
             val.x.empty() ? "PSNR of training batches (dB)"
                           : "PSNR: training batches (green), validation " + renderer + " (red)");
  video::write_png(png, img);
  return true;
}

}  // namespace th::train
