#include "inference/free_view.hpp"

#include <spdlog/spdlog.h>
#include <torch/torch.h>
#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <chrono>
#include <map>
#include <optional>
#include <sstream>

#include "core/config_io.hpp"
#include "core/error.hpp"
#include "core/progress.hpp"
#include "core/resources.hpp"
#include "dist/communicator.hpp"
#include "dist/shard.hpp"
#include "inference/request.hpp"
#include "io/files.hpp"
#include "model/precision.hpp"
#include "video/contact_sheet.hpp"
#include "video/frame_writer.hpp"

namespace th::inference {
namespace fs = std::filesystem;

torch::Tensor scale_intrinsics(const torch::Tensor& K, double sx, double sy) {
  auto out = K.to(torch::kFloat64).clone();
  out[0] *= sx;
  out[1] *= sy;
  out[2] = torch::tensor({0.0, 0.0, 1.0}, torch::kFloat64);
  return out;
}

std::vector<int> parse_frame_range(const std::string& text) {
  std::vector<int> parts;
  std::stringstream ss(text);
  std::string item;
  while (std::getline(ss, item, ':')) {
    size_t used = 0;
    int value = 0;
    try {
      value = std::stoi(item, &used);
    } catch (const std::exception&) {
      used = 0;
    }
    if (item.empty() || used != item.size())
      fail("frame range '", text, "': expected FRAME, BEGIN:END or BEGIN:END:STEP");
    parts.push_back(value);
  }
  if (!text.empty() && text.back() == ':') parts.clear();
  if (parts.size() == 1) return parts;
  if (parts.size() < 2 || parts.size() > 3)
    fail("frame range '", text, "': expected FRAME, BEGIN:END or BEGIN:END:STEP");
  const int64_t begin = parts[0], end = parts[1], step = parts.size() == 3 ? parts[2] : 1;
  if (step <= 0) fail("frame range '", text, "': the step must be positive");
  if (begin < 0) fail("frame range '", text, "': frames are numbered from 0");
  if (end <= begin) fail("frame range '", text, "' is empty");
  // Counted before anything is allocated (int64: no overflow near INT_MAX).
  const int64_t count = (end - begin + step - 1) / step;
  if (count > kMaxVideoFrames)
    fail("frame range '", text, "' holds ", count, " frames, more than a video may have (",
         kMaxVideoFrames, ")");
  std::vector<int> frames;
  for (int64_t f = begin; f < end; f += step) frames.push_back(int(f));
  return frames;
}

namespace {

// What makes two runs' frames interchangeable; written to request.yaml. Beside the request
// itself (person, frames, cameras, size, checkpoint), every setting that changes the pixels:
// the precision the products resolve to on this device, the split setting (its reference views)
// and the data, model and render keys of changes_pixels.
std::string describe(const Session& session, const VideoRequest& r, const std::string& human,
                     const std::vector<int>& frames, int width, int height, int count) {
  const Config& c = session.config();
  YAML::Emitter y;
  y << YAML::BeginMap << YAML::Key << "checkpoint" << YAML::Value << session.checkpoint_id();
  y << YAML::Key << "human" << YAML::Value << human;
  y << YAML::Key << "frames" << YAML::Value << YAML::Flow << frames;
  const char* kind = r.cameras == VideoRequest::Cameras::Orbit      ? "orbit"
                     : r.cameras == VideoRequest::Cameras::PathFile ? "path_file"
                                                                    : "dataset_camera";
  y << YAML::Key << "cameras" << YAML::Value << kind;
  if (r.cameras == VideoRequest::Cameras::PathFile)
    y << YAML::Key << "path_file" << YAML::Value
      << fs::absolute(r.path_file).lexically_normal().string();
  if (r.cameras == VideoRequest::Cameras::Dataset)
    y << YAML::Key << "camera" << YAML::Value << r.camera;
  if (r.cameras == VideoRequest::Cameras::Orbit) y << YAML::Key << "view" << YAML::Value << r.view;
  y << YAML::Key << "width" << YAML::Value << width << YAML::Key << "height" << YAML::Value
    << height;
  y << YAML::Key << "video_frames" << YAML::Value << count;
  if (r.renderer) {
    y << YAML::Key << "renderer" << YAML::Value << r.renderer_id;
    for (const auto& [key, value] : r.renderer_keys) y << YAML::Key << key << YAML::Value << value;
  }
  y << YAML::Key << "settings" << YAML::Value;
  emit_pixel_settings(y, c, session.device());
  y << YAML::EndMap;
  return std::string(y.c_str()) + "\n";
}

}  // namespace

VideoPlan plan_video(const Session& session, const VideoRequest& request) {
  const int h = session.find_human(request.human);
  const auto& human = session.human(h);
  std::vector<int> frames = request.frames;
  if (frames.empty()) {
    const auto listed = session.setting_frames(h);
    if (listed.empty())
      fail("setting '", session.config().eval.setting, "' lists no frames of ", human.name());
    frames = {listed.front()};
  }
  for (int f : frames)
    if (f < 0 || f >= human.num_frames())
      fail(human.name(), ": frame ", f, " out of range [0, ", human.num_frames(), ")");

  // The camera whose image the output is modelled on: its K (at data.ratio) and size.
  using Cameras = VideoRequest::Cameras;
  const int base_view = request.cameras == Cameras::Dataset
                            ? data::camera_index(human, request.camera, "--camera")
                            : request.view;
  if (base_view < 0 || base_view >= human.num_cameras())
    fail(human.name(), ": camera ", base_view, " out of range [0, ", human.num_cameras(), ")");
  spdlog::info("{}: camera '{}' (index {}){}", human.name(), human.camera_name(base_view),
               base_view,
               request.cameras == Cameras::Dataset ? "" : ": the orbit's intrinsics and size");
  PreparedFrame prepared = session.prepare(h, frames.front(), base_view);
  const int src_w = int(prepared.sample.target_image.size(1)),
            src_h = int(prepared.sample.target_image.size(0));
  int width = request.width > 0 ? request.width : src_w;
  int height = request.height > 0 ? request.height : src_h;

  // The camera of every video frame.
  const auto base = session.dataset_camera(prepared, base_view);
  const auto K = scale_intrinsics(base.K, double(width) / src_w, double(height) / src_h);
  std::vector<video::PathCamera> cameras;  // the path, cycled over the video
  int count = 0;
  std::vector<video::PathCamera> shots;
  if (request.cameras == Cameras::Orbit) {
    std::vector<torch::Tensor> Rs, Ts;
    for (int c = 0; c < human.num_cameras(); ++c) {
      Rs.push_back(human.camera(c).R);
      Ts.push_back(human.camera(c).T);
    }
    const auto orbit = video::make_orbit(torch::stack(Rs), torch::stack(Ts));
    const int n = request.orbit_views > 0 ? request.orbit_views
                                          : (frames.size() > 1 ? int(frames.size()) : 36);
    if (n > kMaxVideoFrames)
      fail("--orbit ", n, ": more views than a video may have (", kMaxVideoFrames, ")");
    count = std::max(int(frames.size()), n);
    std::map<int, torch::Tensor> centers;  // one body per frame shown, not per view
    for (int k = 0; k < count; ++k) {      // looking at the centre of the body of the frame shown
      const int frame = frames[size_t(k) % frames.size()];
      auto it = centers.find(frame);
      if (it == centers.end()) it = centers.emplace(frame, session.body_center(h, frame)).first;
      const double theta = 2.0 * M_PI * double(k % n) / double(n);
      shots.push_back(video::orbit_camera(orbit, K, it->second, theta));
    }
  } else {
    if (request.cameras == Cameras::PathFile) {
      const auto path = video::read_camera_path(request.path_file);
      if (path.cameras.empty())
        fail("camera path '", request.path_file.string(), "' has no cameras");
      cameras = path.cameras;
      if (request.width <= 0 && path.width > 0) width = path.width;
      if (request.height <= 0 && path.height > 0) height = path.height;
    } else {
      cameras = {{K, base.R, base.T}};
    }
    count = int(std::max(frames.size(), cameras.size()));
    for (int k = 0; k < count; ++k) shots.push_back(cameras[size_t(k) % cameras.size()]);
  }

  // What it costs, refused before anything is written when it cannot fit.
  resources::check(session.render_estimate(prepared, width, height, count),
                   session.config().max_memory_gb);
  VideoPlan plan;
  plan.human = h;
  plan.human_name = human.name();
  plan.frames = std::move(frames);
  plan.base_view = base_view;
  plan.width = width;
  plan.height = height;
  plan.count = count;
  plan.shots = std::move(shots);
  plan.prepared = std::move(prepared);
  return plan;
}

VideoSummary render_video(const Session& session, const VideoRequest& request,
                          const fs::path& out_dir, dist::Communicator* comm) {
  VideoPlan plan = plan_video(session, request);
  const int h = plan.human, base_view = plan.base_view, width = plan.width, height = plan.height,
            count = plan.count;
  const auto& frames = plan.frames;
  const auto& shots = plan.shots;
  const auto& human = session.human(h);
  PreparedFrame& prepared = plan.prepared;
  const bool writes = !out_dir.empty();
  const fs::path frames_dir = out_dir / "frames";

  // Resume only what the same request wrote (rank 0, or the only process, owns the folder).
  std::optional<video::FrameWriter> writer;
  std::vector<int64_t> todo;  // video frames still to render
  VideoSummary summary;
  summary.frames = count;
  summary.frames_dir = frames_dir;
  if (writes) {
    fs::create_directories(out_dir);
    // Frames are resumed only under the request that made them: another one (a setting that
    // changes pixels included) is refused by name, or with `force` its frames are rendered again.
    const fs::path request_file = out_dir / "request.yaml";
    const std::string wanted =
        describe(session, request, human.name(), frames, width, height, count);
    const bool known = fs::exists(request_file);
    const std::string before = known ? io::read_file(request_file) : "";
    if (known ? before != wanted : fs::exists(frames_dir)) {
      if (!request.force && !known)
        fail("'", out_dir.string(),
             "' holds frames/ without the request.yaml that says what made them; use "
             "another --out, or --force to render them again");
      if (!request.force) {
        const std::string changed = request_differences(before, wanted, "frames");
        fail("'", out_dir.string(), "' holds frames of another request",
             changed.empty() ? "" : ": " + changed, " (see ", request_file.string(),
             "); use another --out, or --force to render them again");
      }
      fs::remove_all(frames_dir);
    }
    io::write_file_atomic(request_file, wanted);
    video::write_camera_path(out_dir / "cameras.yaml", {shots, width, height});
    video::FrameWriterOptions wo;
    wo.dir = frames_dir;
    wo.video_name = "../video.mp4";
    writer.emplace(wo);
    for (int k = 0; k < count; ++k)
      if (!writer->has_frame(k)) todo.push_back(k);
    summary.skipped = count - int(todo.size());
    spdlog::info(
        "video: {} frames of {} ({} body frame{}), {}x{}{}", count, human.name(), frames.size(),
        frames.size() > 1 ? "s" : "", width, height,
        summary.skipped ? fmt::format(", {} already written (resumed)", summary.skipped) : "");
  }
  // Which frames are left is rank 0's to say; each rank then takes every ranks-th of them.
  std::vector<std::vector<int64_t>> assignment{todo};
  if (comm) {
    dist::broadcast_items(*comm, todo, "the frames left to render");
    std::vector<std::vector<int64_t>> single;
    for (const int64_t k : todo) single.push_back({k});
    assignment = dist::balance(single, std::vector<double>(single.size(), 1.0), comm->world_size());
    if (comm->rank() == 0)
      spdlog::info("video: {} frames to render over {} ranks", todo.size(), comm->world_size());
  }

  Progress progress("render",
                    comm && comm->rank() != 0 ? int64_t(assignment[size_t(comm->rank())].size())
                                              : int64_t(todo.size()),
                    "frame");
  double render_seconds = 0;
  auto work = [&](int64_t k) {
    const int frame = frames[size_t(k) % frames.size()];
    const auto t0 = std::chrono::steady_clock::now();
    if (prepared.frame != frame) prepared = session.prepare(h, frame, base_view);
    const auto image = request.renderer
                           ? request.renderer(prepared, shots[size_t(k)], width, height)
                           : session.render(prepared, shots[size_t(k)], width, height);
    dist::Record rec;
    rec.put(std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
    rec.put(video::encode_png(video::to_bgr8(image), "video frame " + std::to_string(k)));
    return rec.bytes();
  };
  auto collect = [&](int64_t k, const std::string& bytes) {
    dist::Record rec(bytes);
    render_seconds += rec.number("seconds");
    const std::string png = rec.text("frame");
    if (writer) io::write_file_atomic(writer->frame_path(int(k)), png);
    ++summary.rendered;
    progress.advance(1, "frame " + std::to_string(k) + " body " +
                            std::to_string(frames[size_t(k) % frames.size()]));
  };
  auto finish = [&] {
    progress.finish();
    summary.seconds_per_frame = summary.rendered ? render_seconds / summary.rendered : 0.0;
    if (!writer) return;
    const auto video = writer->write_video(count);
    summary.video_written = video.written;
    summary.video_message = video.message;
    if (request.contact_sheet_frames > 0) {
      std::vector<fs::path> paths;
      for (int k = 0; k < count; ++k) paths.push_back(writer->frame_path(k));
      const int columns = std::min(6, std::min(count, request.contact_sheet_frames));
      summary.contact_sheet = out_dir / "contact_sheet.png";
      video::write_png(
          summary.contact_sheet,
          video::contact_sheet(paths, request.contact_sheet_frames, columns, std::min(width, 256)));
    }
  };
  if (comm) {
    comm->sharded(assignment, work, collect, finish, "rendering the video");
  } else {
    for (const int64_t k : todo) collect(k, work(k));
    finish();
  }
  return summary;
}

}  // namespace th::inference
