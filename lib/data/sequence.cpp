#include "data/sequence.hpp"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <fstream>
#include <limits>
#include <numeric>
#include <opencv2/calib3d.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "core/config_io.hpp"
#include "core/error.hpp"
#include "core/files.hpp"
#include "data/easymocap.hpp"
#include "data/zju_mocap.hpp"
#include "geometry/camera.hpp"

namespace th::data {
namespace fs = std::filesystem;

namespace {

// A JPEG ends with the EOI marker (FF D9); libjpeg decodes a truncated file with only a warning
// (grey lower rows), so a missing marker is an error here.
bool jpeg_truncated(const fs::path& path) {
  std::ifstream in(path, std::ios::binary | std::ios::ate);
  const auto size = static_cast<std::streamoff>(in.tellg());
  if (!in || size < 4) return true;
  const std::streamoff tail = std::min<std::streamoff>(size, 64);
  std::string bytes(static_cast<size_t>(tail), '\0');
  in.seekg(size - tail);
  in.read(bytes.data(), tail);
  return bytes.find("\xFF\xD9") == std::string::npos;
}

// uint8 -> float32 in [0, 1] as the reference computes it: a float32 division by 255 (OpenCV's
// scaled conversion multiplies by 1/255 instead, which differs in the last bit for some values).
cv::Mat to_unit_float(const cv::Mat& u8) {
  cv::Mat out(u8.size(), CV_MAKETYPE(CV_32F, u8.channels()));
  const cv::Mat src = u8.isContinuous() ? u8 : u8.clone();
  const uint8_t* in = src.ptr<uint8_t>();
  float* o = out.ptr<float>();
  for (size_t i = 0, n = src.total() * src.channels(); i < n; ++i)
    o[i] = static_cast<float>(in[i]) / 255.0f;
  return out;
}

}  // namespace

const Camera& HumanSequence::camera(int index) const {
  if (index < 0 || index >= num_cameras())
    fail(name_, ": camera ", index, " does not exist (", num_cameras(), " cameras)");
  return cameras_[size_t(index)];
}

const std::string& HumanSequence::camera_name(int index) const {
  camera(index);
  return camera_names_[size_t(index)];
}

DataLayout detect_layout(const fs::path& dir) {
  std::error_code ec;
  // exists, not is_regular_file: a FIFO or device in their place is refused by the reader, by name.
  const bool zju = exists_or_fail(dir / "annots.npy");
  const bool easymocap = exists_or_fail(dir / "intri.yml") || exists_or_fail(dir / "extri.yml");
  if (zju && easymocap)
    fail("'", dir.string(),
         "' holds both annots.npy (ZJU-MoCap's layout) and intri.yml/extri.yml (EasyMocap's): ",
         "set data.layout to zju_mocap or easymocap");
  if (zju) return DataLayout::zju_mocap;
  if (easymocap) return DataLayout::easymocap;
  if (!fs::is_directory(dir, ec)) fail("human folder '", dir.string(), "' does not exist");
  fail("'", dir.string(),
       "' holds neither annots.npy (ZJU-MoCap's layout) nor intri.yml and extri.yml ",
       "(EasyMocap's layout): is data.root the folder holding one folder per person?");
}

std::shared_ptr<HumanSequence> open_human(const fs::path& dir, const OpenOptions& options) {
  DataLayout layout = options.layout;
  if (layout == DataLayout::automatic) {
    layout = detect_layout(dir);
    spdlog::info("{}: {} layout (data.layout: auto)", dir.string(), config::name_of(layout));
  }
  if (layout == DataLayout::easymocap) return EasyMocapSequence::open(dir, options);
  return ZjuMocapSequence::open(dir);
}

int camera_index(const HumanSequence& human, const std::string& value, const std::string& where,
                 bool index_only) {
  if (!index_only)
    for (int c = 0; c < human.num_cameras(); ++c)
      if (human.camera_name(c) == value) return c;
  const auto number = config::decimal_integer(value);
  if (number && *number >= 0 && *number < human.num_cameras()) return int(*number);
  if (number)
    fail(where, ": camera ", *number, " does not exist for ", human.name(), " (",
         human.num_cameras(), " cameras, indices 0 to ", human.num_cameras() - 1, ")");
  std::string names;
  for (int c = 0; c < human.num_cameras() && c < 40; ++c)
    names += (c ? ", " : "") + human.camera_name(c);
  fail(where, ": ", human.name(), " has no camera '", value, "' (its cameras: ", names,
       human.num_cameras() > 40 ? ", ..." : "", ")");
}

std::vector<int> spread_cameras(const HumanSequence& human, const torch::Tensor& body_vertices,
                                int count) {
  const int n = human.num_cameras();
  if (count > n)
    fail(human.name(), ": ", count, " reference views asked for but it has ", n, " cameras");
  if (count == 1) return {0};
  // Camera centres C = -R^T T, relative to the body's centre; the ring's normal is the direction
  // in which the centres vary least.
  std::vector<torch::Tensor> centres;
  for (int c = 0; c < n; ++c) {
    const Camera& cam = human.camera(c);
    centres.push_back(-cam.R.transpose(0, 1).matmul(cam.T).reshape({3}));
  }
  const torch::Tensor C = torch::stack(centres);
  const torch::Tensor body = body_vertices.to(torch::kFloat64).mean(0);
  const torch::Tensor centred = C - C.mean(0);
  const auto svd = torch::linalg_svd(centred, true);  // all three directions, even for 2 cameras
  const torch::Tensor normal = std::get<2>(svd)[2];
  // An in-plane basis (u, v) around the normal.
  torch::Tensor seed = torch::zeros({3}, torch::kFloat64);
  seed[normal.abs().argmin().item<int64_t>()] = 1.0;
  const torch::Tensor u = torch::linalg_cross(normal, seed);
  const torch::Tensor u_unit = u / u.norm();
  const torch::Tensor v_unit = torch::linalg_cross(normal, u_unit);
  const torch::Tensor rel = C - body;
  const auto x = rel.matmul(u_unit), y = rel.matmul(v_unit);
  std::vector<double> azimuth(static_cast<size_t>(n));
  for (int c = 0; c < n; ++c)
    azimuth[size_t(c)] = std::atan2(y[c].item<double>(), x[c].item<double>());

  // Every subset of `count` cameras (enumerated in lexicographic order, so ties keep the first).
  constexpr double kTwoPi = 6.283185307179586;
  std::vector<int> pick(static_cast<size_t>(count)), best;
  std::iota(pick.begin(), pick.end(), 0);
  double best_max = std::numeric_limits<double>::infinity(), best_sq = best_max;
  const auto score = [&](const std::vector<int>& s, double& max_gap, double& sum_sq) {
    std::vector<double> a;
    for (int c : s) a.push_back(azimuth[size_t(c)]);
    std::sort(a.begin(), a.end());
    max_gap = 0, sum_sq = 0;
    for (size_t i = 0; i < a.size(); ++i) {
      const double gap = i + 1 < a.size() ? a[i + 1] - a[i] : a.front() + kTwoPi - a.back();
      max_gap = std::max(max_gap, gap);
      sum_sq += gap * gap;
    }
  };
  constexpr double kTie = 1e-9;
  int64_t visited = 0;
  for (;;) {
    double m, q;
    score(pick, m, q);
    if (m < best_max - kTie || (m < best_max + kTie && q < best_sq - kTie))
      best_max = m, best_sq = q, best = pick;
    // Next combination; beyond a million the search stops with the best found (many cameras).
    if (++visited >= 1000000) break;
    int i = count - 1;
    while (i >= 0 && pick[size_t(i)] == n - count + i) --i;
    if (i < 0) break;
    ++pick[size_t(i)];
    for (int j = i + 1; j < count; ++j) pick[size_t(j)] = pick[size_t(j - 1)] + 1;
  }
  return best;
}

void require_finite(const torch::Tensor& t, const fs::path& file, const std::string& what) {
  const auto bad = (~torch::isfinite(t)).reshape({-1}).nonzero();
  if (bad.numel() > 0) {
    const int64_t i = bad[0][0].item<int64_t>();
    fail("'", file.string(), "': ", what, " holds ", t.reshape({-1})[i].item<double>(),
         " at index ", i, " (", bad.size(0), " non-finite value", bad.size(0) > 1 ? "s" : "", ")");
  }
}

cv::Mat read_image(const fs::path& path, int flags) {
  refuse_special_file(path, "image");
  exists_or_fail(path);  // a loop of links is not "missing or corrupt"
  cv::Mat img = cv::imread(path.string(), flags);
  if (img.empty()) fail("cannot read image '", path.string(), "' (missing or corrupt)");
  std::string ext = path.extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(),
                 [](unsigned char c) { return std::tolower(c); });
  if ((ext == ".jpg" || ext == ".jpeg") && jpeg_truncated(path))
    fail("image '", path.string(), "' is truncated (no JPEG end marker)");
  return img;
}

cv::Mat read_mask(const fs::path& path) {
  const cv::Mat m = read_image(path, cv::IMREAD_UNCHANGED);
  std::vector<cv::Mat> channels;
  cv::split(m, channels);
  if (channels.size() == 4) {
    double lowest = 0, highest = 0;
    cv::minMaxLoc(channels[3], &lowest, &highest);
    if (lowest < highest) return channels[3] != 0;
    channels.pop_back();  // an opaque (or wholly transparent) image: its colours mark the person
  }
  cv::Mat person = channels.front() != 0;
  for (size_t c = 1; c < channels.size(); ++c) person |= channels[c] != 0;
  return person;
}

cv::Mat HumanSequence::load_mask(int frame, int cam) const {
  const std::vector<fs::path> files = mask_files(frame, cam);
  cv::Mat mask;
  for (const fs::path& file : files) {
    const cv::Mat m = read_mask(file);
    if (!mask.empty() && m.size() != mask.size())
      fail("'", file.string(), "' is ", m.cols, "x", m.rows, " but '", files.front().string(),
           "' is ", mask.cols, "x", mask.rows);
    mask = mask.empty() ? m : (mask | m);
  }
  return mask / 255;  // 0/1
}

ViewImage load_view(const HumanSequence& human, int frame, int cam, const ViewOptions& o) {
  const fs::path path = human.image_path(frame, cam);
  cv::Mat bgr = read_image(path, cv::IMREAD_COLOR);
  // Smaller images leave the encoder's last stage (stride 32) without a pixel to look at.
  constexpr int kMinSide = 8;
  const cv::Size size(int(bgr.cols * o.ratio), int(bgr.rows * o.ratio));
  if (size.width < kMinSide || size.height < kMinSide)
    fail("image '", path.string(), "' is ", bgr.cols, "x", bgr.rows, " pixels; at data.ratio ",
         o.ratio, " it would be ", size.width, "x", size.height, ", below the ", kMinSide, "x",
         kMinSide, " the network needs");
  cv::Mat rgb;
  cv::cvtColor(bgr, rgb, cv::COLOR_BGR2RGB);
  rgb = to_unit_float(rgb);
  cv::Mat mask = human.load_mask(frame, cam);
  if (mask.size() != rgb.size())
    fail("mask of '", path.string(), "' is ", mask.cols, "x", mask.rows, " but the image is ",
         rgb.cols, "x", rgb.rows);
  if (o.jitter) apply_jitter(rgb, *o.jitter);

  const auto mark_band = [](cv::Mat& m) {  // METHOD 2.1 step 6: target mask only
    const cv::Mat kernel = cv::Mat::ones(5, 5, CV_8U);
    cv::Mat eroded, dilated;
    cv::erode(m, eroded, kernel);
    cv::dilate(m, dilated, kernel);
    m.setTo(100, (dilated - eroded) == 1);
  };
  if (o.border_band && o.band_before_undistort) mark_band(mask);

  const Camera& calib = human.camera(cam);
  // The reference undistorts with K and D rounded to float32 [parity].
  const auto f32 = [](const torch::Tensor& t) { return t.to(torch::kFloat32).to(torch::kFloat64); };
  const cv::Mat K = geometry::to_cv(f32(calib.K)), D = geometry::to_cv(f32(calib.D));
  cv::Mat und_rgb, und_mask;
  cv::undistort(rgb, und_rgb, K, D);
  cv::undistort(mask, und_mask, K, D);
  if (o.border_band && !o.band_before_undistort) mark_band(und_mask);

  ViewImage view;
  if (size != rgb.size()) {
    cv::resize(und_rgb, view.rgb, size, 0, 0, cv::INTER_AREA);
    cv::resize(und_mask, view.mask, size, 0, 0, cv::INTER_NEAREST);
  } else {
    view.rgb = und_rgb;
    view.mask = und_mask;
  }
  view.rgb.setTo(cv::Scalar::all(0), view.mask == 0);
  view.camera = calib;
  view.camera.K = calib.K.clone();
  view.camera.K.slice(0, 0, 2) *= o.ratio;
  return view;
}

}  // namespace th::data
