// Frame output for free-viewpoint video (METHOD 7): PNG frames, resumable skipping, the mp4 (or a
// clear message when OpenCV cannot write one) and the contact sheet.

#include <torch/torch.h>

#include <catch2/catch.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/videoio.hpp>

#include "core/error.hpp"
#include "support/test_env.hpp"
#include "video/contact_sheet.hpp"
#include "video/frame_writer.hpp"

using th::video::FrameWriter;
using th::video::FrameWriterOptions;

namespace {

// Frame k: a uniform colour with a bright square whose position moves with k; (H, W, 3) RGB.
torch::Tensor frame(int k, int64_t h = 48, int64_t w = 64) {
  auto img = torch::zeros({h, w, 3});
  img.select(2, 0).fill_(0.2f * (k % 5));
  img.select(2, 2).fill_(0.5f);
  img.slice(0, 10, 20).slice(1, 4 * k % 40, 4 * k % 40 + 10).fill_(1.0f);
  return img;
}

}  // namespace

TEST_CASE("frames are PNG files frame_%04d.png with the rendered colours", "[video][frames]") {
  const auto dir = th::test::scratch_dir("video_frames");
  FrameWriter writer({dir / "orbit"});
  writer.write_frame(3, frame(3));
  CHECK(writer.frame_path(3) == dir / "orbit" / "frame_0003.png");
  const cv::Mat back = cv::imread(writer.frame_path(3).string(), cv::IMREAD_COLOR);
  REQUIRE(back.rows == 48);
  REQUIRE(back.cols == 64);
  // RGB (0.6, 0, 0.5) -> BGR (128, 0, 153) after x 255 and rounding (half to even).
  CHECK(back.at<cv::Vec3b>(40, 60) == cv::Vec3b(128, 0, 153));
  CHECK(back.at<cv::Vec3b>(15, 15) == cv::Vec3b(255, 255, 255));
  // Nothing but the frame is left in the folder (written through a temporary + rename).
  int files = 0;
  for (const auto& entry : std::filesystem::directory_iterator(dir / "orbit")) {
    (void)entry;
    ++files;
  }
  CHECK(files == 1);
}

TEST_CASE("resuming skips frames already written", "[video][frames]") {
  const auto dir = th::test::scratch_dir("video_resume");
  const int n = 6;
  auto render_all = [&](int stop_after) {  // a run that may be interrupted
    FrameWriter writer({dir});
    int rendered = 0;
    for (int k = 0; k < n && rendered < stop_after; ++k) {
      if (writer.has_frame(k)) continue;
      writer.write_frame(k, frame(k));
      ++rendered;
    }
    return rendered;
  };
  CHECK(render_all(4) == 4);  // interrupted after 4 frames
  FrameWriter writer({dir});
  CHECK(writer.missing(n) == 2);
  CHECK(writer.has_frame(3));
  CHECK_FALSE(writer.has_frame(4));
  const auto before = std::filesystem::last_write_time(writer.frame_path(0));
  CHECK(render_all(100) == 2);  // the second run renders only the rest
  CHECK(writer.missing(n) == 0);
  CHECK(std::filesystem::last_write_time(writer.frame_path(0)) == before);
  CHECK(render_all(100) == 0);
}

TEST_CASE("mp4 at 30 fps from the frames, or a clear fallback message", "[video][frames]") {
  const auto dir = th::test::scratch_dir("video_mp4");
  FrameWriter writer({dir});
  const int n = 12;
  for (int k = 0; k < n; ++k) writer.write_frame(k, frame(k));
  const auto result = writer.write_video(n);
  INFO(result.message);
  if (result.written) {
    CHECK(result.path == dir / "video.mp4");
    cv::VideoCapture cap(result.path.string());
    REQUIRE(cap.isOpened());
    CHECK(cap.get(cv::CAP_PROP_FPS) == Approx(30.0));
    int frames = 0;
    cv::Mat f;
    while (cap.read(f)) {
      CHECK(f.cols == 64);
      CHECK(f.rows == 48);
      ++frames;
    }
    CHECK(frames == n);
  } else {
    CHECK_THAT(result.message,
               Catch::Contains("cannot write") && Catch::Contains("PNG files in '" + dir.string()));
  }

  // A container OpenCV has no writer for: no video, the message says so and where the frames
  // are, and the frames are untouched.
  FrameWriterOptions odd{dir};
  odd.video_name = "video.notavideo";
  const auto fallback = FrameWriter(odd).write_video(n);
  CHECK_FALSE(fallback.written);
  CHECK_THAT(fallback.message, Catch::Contains("cannot write") &&
                                   Catch::Contains("video.notavideo") &&
                                   Catch::Contains("12 frames are PNG files in"));
  CHECK(writer.missing(n) == 0);

  // A missing frame is a user error naming the file.
  CHECK_THROWS_WITH(writer.write_video(n + 1), Catch::Contains("frame_0012.png"));
}

TEST_CASE("contact sheet: evenly spaced frames in a labelled grid", "[video][contact_sheet]") {
  CHECK(th::video::evenly_spaced(36, 4) == std::vector<int>{0, 12, 23, 35});
  CHECK(th::video::evenly_spaced(3, 5) == std::vector<int>{0, 1, 2});
  CHECK(th::video::evenly_spaced(10, 1) == std::vector<int>{0});

  const auto dir = th::test::scratch_dir("video_sheet");
  FrameWriter writer({dir});
  std::vector<std::filesystem::path> files;
  for (int k = 0; k < 9; ++k) {
    writer.write_frame(k, frame(k));
    files.push_back(writer.frame_path(k));
  }
  // 4 of 9 frames (0, 3, 5, 8), 2 per row, thumbnails 32 px wide (24 tall), 4 px gaps.
  const cv::Mat sheet = th::video::contact_sheet(files, 4, 2, 32);
  cv::imwrite((dir / "sheet.png").string(), sheet);
  CHECK(sheet.cols == 2 * 32 + 3 * 4);
  CHECK(sheet.rows == 2 * 24 + 3 * 4);
  // Bottom-right cell is frame 8: RGB (0.6, 0, 0.5) -> BGR (128, 0, 153) away from the square
  // and the label; top-left is frame 0: (0, 0, 0.5).
  CHECK(sheet.at<cv::Vec3b>(4 + 24 + 4 + 20, 4 + 32 + 4 + 28) == cv::Vec3b(128, 0, 153));
  CHECK(sheet.at<cv::Vec3b>(4 + 20, 4 + 28) == cv::Vec3b(128, 0, 0));
  CHECK(sheet.at<cv::Vec3b>(1, 1) == cv::Vec3b(0, 0, 0));  // gap

  files.push_back(dir / "missing.png");
  CHECK_THROWS_WITH(th::video::contact_sheet(files, 10, 5, 32), Catch::Contains("missing.png"));
}
