#pragma once
// Free-viewpoint video output (METHOD 7: frames -> PNG and an mp4 at 30 fps).
//
// Resumable: frames are written atomically (temporary file + rename), so a frame file that
// exists is complete and an interrupted run can skip it (has_frame). The mp4 is assembled from
// the PNG files at the end, so frames rendered by earlier runs are included.

#include <torch/types.h>

#include <filesystem>
#include <opencv2/core.hpp>
#include <string>

namespace th::video {

struct FrameWriterOptions {
  std::filesystem::path dir;      // created if missing
  std::string prefix = "frame_";  // frames are <prefix>%04d.png
  std::string video_name = "video.mp4";
  double fps = 30.0;            // METHOD 7
  std::string fourcc = "mp4v";  // MPEG-4 part 2: what OpenCV's FFmpeg backend writes
};

// What write_video did; `message` is one line for the user in both cases.
struct VideoResult {
  bool written = false;
  std::filesystem::path path;  // the mp4 (only meaningful when written)
  std::string message;
};

class FrameWriter {
 public:
  explicit FrameWriter(FrameWriterOptions options);

  std::filesystem::path frame_path(int index) const;
  // True when frame `index` was already written (by this or an earlier run): skip it.
  bool has_frame(int index) const;
  // Number of frames among 0..n-1 still to write.
  int missing(int n) const;

  // image: BGR CV_8UC3 (as cv::imwrite takes it). Throws th::Error naming the file on failure.
  void write_frame(int index, const cv::Mat& bgr);
  // rgb: (H, W, 3) float in [0, 1] (the renderer's output), clamped and rounded to 8 bits.
  void write_frame(int index, const torch::Tensor& rgb);

  // Encodes frames 0..n-1 (all must exist, same size) into dir/video_name with cv::VideoWriter
  // (4:2:0 codecs drop the last row/column of odd-sized frames; the PNGs keep them).
  // If OpenCV cannot open an mp4 writer (a build without FFmpeg/GStreamer) or writes nothing,
  // returns written = false with a message saying so and where the PNG frames are; the frames
  // are never touched. Throws th::Error if a frame is missing or unreadable.
  VideoResult write_video(int n) const;

  const FrameWriterOptions& options() const { return options_; }

 private:
  FrameWriterOptions options_;
};

// (H, W, 3) float RGB in [0, 1] -> BGR CV_8UC3.
cv::Mat to_bgr8(const torch::Tensor& rgb);

// Writes an image as PNG atomically. Throws th::Error naming the path.
void write_png(const std::filesystem::path& path, const cv::Mat& image);
// An image's PNG bytes; throws th::Error naming `what` when it cannot be encoded.
std::string encode_png(const cv::Mat& image, const std::string& what);

}  // namespace th::video
