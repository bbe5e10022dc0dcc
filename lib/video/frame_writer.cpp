#include "video/frame_writer.hpp"

#include <torch/torch.h>

#include <cstdio>
#include <opencv2/core/utils/logger.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/videoio.hpp>
#include <vector>

#include "core/error.hpp"
#include "core/files.hpp"
#include "io/files.hpp"

namespace th::video {
namespace {

cv::Mat read_frame(const std::filesystem::path& path) {
  std::error_code ec;
  if (!std::filesystem::is_regular_file(path, ec)) fail("frame '", path.string(), "' is missing");
  cv::Mat image = cv::imread(path.string(), cv::IMREAD_COLOR);
  if (image.empty()) fail("cannot read frame '", path.string(), "'");
  return image;
}

// OpenCV logs every backend it tries while opening a writer; the user gets our one line instead.
class QuietOpenCV {
 public:
  QuietOpenCV() : level_(cv::utils::logging::setLogLevel(cv::utils::logging::LOG_LEVEL_SILENT)) {}
  ~QuietOpenCV() { cv::utils::logging::setLogLevel(level_); }

 private:
  cv::utils::logging::LogLevel level_;
};

}  // namespace

cv::Mat to_bgr8(const torch::Tensor& rgb) {
  TORCH_CHECK(rgb.dim() == 3 && rgb.size(2) == 3, "to_bgr8: rgb must be (H, W, 3), got ",
              rgb.sizes());
  auto bgr = (rgb.detach().to(torch::kCPU, torch::kFloat32).flip({2}) * 255.f)
                 .round()
                 .clamp(0, 255)
                 .to(torch::kUInt8)
                 .contiguous();
  return cv::Mat(static_cast<int>(rgb.size(0)), static_cast<int>(rgb.size(1)), CV_8UC3,
                 bgr.data_ptr<uint8_t>())
      .clone();
}

std::string encode_png(const cv::Mat& image, const std::string& what) {
  std::vector<uchar> bytes;
  if (image.empty() || !cv::imencode(".png", image, bytes))
    fail("cannot encode ", what, " as PNG (", image.cols, "x", image.rows, ", type ", image.type(),
         ")");
  return std::string(reinterpret_cast<const char*>(bytes.data()), bytes.size());
}

void write_png(const std::filesystem::path& path, const cv::Mat& image) {
  io::write_file_atomic(path, encode_png(image, "'" + path.string() + "'"));
}

FrameWriter::FrameWriter(FrameWriterOptions options) : options_(std::move(options)) {
  std::error_code ec;
  std::filesystem::create_directories(options_.dir, ec);
  if (ec) fail("cannot create output folder '", options_.dir.string(), "': ", ec.message());
  TORCH_CHECK(options_.fps > 0, "FrameWriter: fps must be > 0");
  TORCH_CHECK(options_.fourcc.size() == 4, "FrameWriter: fourcc must have 4 characters");
}

std::filesystem::path FrameWriter::frame_path(int index) const {
  char number[32];
  std::snprintf(number, sizeof(number), "%04d", index);
  return options_.dir / (options_.prefix + number + ".png");
}

bool FrameWriter::has_frame(int index) const {
  std::error_code ec;
  const auto p = frame_path(index);
  return std::filesystem::is_regular_file(p, ec) && std::filesystem::file_size(p, ec) > 0;
}

int FrameWriter::missing(int n) const {
  int count = 0;
  for (int i = 0; i < n; ++i) count += has_frame(i) ? 0 : 1;
  return count;
}

void FrameWriter::write_frame(int index, const cv::Mat& bgr) {
  TORCH_CHECK(bgr.type() == CV_8UC3, "write_frame: expected a BGR CV_8UC3 image");
  write_png(frame_path(index), bgr);
}

void FrameWriter::write_frame(int index, const torch::Tensor& rgb) {
  write_frame(index, to_bgr8(rgb));
}

VideoResult FrameWriter::write_video(int n) const {
  TORCH_CHECK(n >= 1, "write_video: n must be >= 1");
  VideoResult result;
  result.path = (options_.dir / options_.video_name).lexically_normal();
  // Every frame is checked before encoding starts: a missing one is the user's error, not a
  // half-written video.
  for (int i = 0; i < n; ++i)
    if (!has_frame(i)) fail("frame '", frame_path(i).string(), "' is missing");
  const cv::Mat first = read_frame(frame_path(0));
  const std::string& f = options_.fourcc;
  // The encoder writes a new file of ours, renamed over the video at the end: a link planted at
  // the video's name is replaced, never written through, and no half-written video is left.
  const std::filesystem::path tmp = create_temporary_beside(result.path);
  struct Discard {
    std::filesystem::path file;
    ~Discard() {
      std::error_code ignored;
      if (!file.empty()) std::filesystem::remove(file, ignored);
    }
  } discard{tmp};
  cv::VideoWriter writer;
  {
    QuietOpenCV quiet;
    writer.open(tmp.string(), cv::VideoWriter::fourcc(f[0], f[1], f[2], f[3]), options_.fps,
                first.size(), true);
  }
  const std::string fallback =
      "; the " + std::to_string(n) + " frames are PNG files in '" + options_.dir.string() + "'";
  if (!writer.isOpened()) {
    result.message = "OpenCV cannot write '" + result.path.string() + "' (fourcc " + f +
                     "; this OpenCV build has no video encoder for it)" + fallback;
    return result;
  }
  for (int i = 0; i < n; ++i) {
    const cv::Mat frame = i == 0 ? first : read_frame(frame_path(i));
    if (frame.size() != first.size())
      fail("frame '", frame_path(i).string(), "' is ", frame.cols, "x", frame.rows,
           ", the video is ", first.cols, "x", first.rows);
    writer.write(frame);
  }
  writer.release();
  std::error_code ec;
  if (std::filesystem::file_size(tmp, ec) == 0 || ec) {
    result.message = "OpenCV opened but wrote nothing to '" + result.path.string() + "'" + fallback;
    return result;
  }
  std::filesystem::rename(tmp, result.path, ec);
  if (ec) fail("cannot write '", result.path.string(), "': ", ec.message());
  discard.file.clear();
  result.written = true;
  result.message = "wrote '" + result.path.string() + "' (" + std::to_string(n) + " frames, " +
                   std::to_string(first.cols) + "x" + std::to_string(first.rows) + ", " + f +
                   " at " + std::to_string(static_cast<int>(options_.fps)) + " fps)";
  return result;
}

}  // namespace th::video
