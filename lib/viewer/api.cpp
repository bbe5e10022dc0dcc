#include "viewer/api.hpp"

#include <spdlog/spdlog.h>
#include <torch/torch.h>

#include <algorithm>
#include <cmath>

#include "bake/march.hpp"

namespace th::viewer {
namespace {

// Cancellation is polled between bands of about kBandSamples samples (whole rows).
constexpr int64_t kBandSamples = int64_t{1} << 18;

// The view's bytes in `format`, with the time since `started` as the stage `stage`.
Api::View encoded(const char* stage, Clock::time_point started, const torch::Tensor& image,
                  const std::string& format) {
  const auto ms = [](Clock::duration d) {
    return std::chrono::duration<double, std::milli>(d).count();
  };
  const auto encoding = Clock::now();
  Api::View view{png(image, format == "jpeg"), ""};
  view.timing = fmt::format("{};dur={:.1f}, encode;dur={:.1f}", stage, ms(encoding - started),
                            ms(Clock::now() - encoding));
  return view;
}

bake::BakeOptions checked_bake_options(const Options& options) {
  bake::BakeOptions bake;
  bake.voxel = options.bake_voxel;
  bake::check_options(bake);
  return bake;
}

}  // namespace

Api::Api(const inference::Session& session, const Options& options,
         const std::atomic<bool>& stopping)
    : session_(session),
      options_(options),
      stopping_(stopping),
      bake_options_(checked_bake_options(options)),
      frames_(session, options.view),
      renderer_(options.render_timeout_s),
      bakes_(
          [this](int h, int f, const std::function<bool()>& cancelled,
                 const std::function<void(double)>& progress) -> std::optional<bake::BakedFrame> {
            // The network runs for one request or bake at a time: the bake holds the renderer
            // while it runs, and exact requests wait behind it as behind a render.
            const auto hold = renderer_.take_for_bake(cancelled);
            if (!hold) return std::nullopt;
            return bake::bake_frame(session_, *frames_.prepared(h, f), bake_options_, nullptr,
                                    progress);
          },
          stopping) {}

std::string Api::info() const {
  Json humans = Json::array();
  for (size_t h = 0; h < session_.dataset().humans().size(); ++h) {
    const auto& person = session_.human(int(h));
    humans.push_back({{"name", person.name()},
                      {"cameras", person.num_cameras()},
                      {"frames", session_.setting_frames(int(h))}});
  }
  Json answer;
  answer["humans"] = std::move(humans);
  answer["samples"] = session_.config().render.samples;
  answer["max_size"] = options_.max_size;
  answer["view"] = options_.view;
  answer["max_samples"] = kMaxSamples;
  answer["render_timeout_s"] = options_.render_timeout_s;
  answer["bake"] = options_.bake;
  answer["bake_voxel"] = options_.bake_voxel;
  answer["baked_views"] = kBakedViews;
  answer["start"] = {{"human", options_.start_human}, {"frame", options_.start_frame}};
  return body(answer);
}

std::string Api::frame_json(const httplib::Request& req) {
  const auto [h, f] = person_frame(req);
  const auto frame = frames_.data(h, f);
  Json cameras = Json::array();
  for (int c = 0; c < session_.human(h).num_cameras(); ++c) {
    const auto cam = session_.dataset_camera(*frame, c);
    const auto R = cam.R, eye = -torch::mv(R.t(), cam.T.flatten());
    const double height = double(frame->sample.target_image.size(0));
    const double fy = cam.K[1][1].item<double>();
    cameras.push_back({{"eye", vec3_json(eye)},
                       {"forward", vec3_json(R[2])},
                       {"up", vec3_json(-R[1])},
                       {"fovy", 2.0 * std::atan(0.5 * height / fy) * 180.0 / M_PI},
                       {"width", frame->sample.target_image.size(1)},
                       {"height", height}});
  }
  Json answer;
  answer["center"] = vec3_json(session_.body_center(h, f));
  answer["references"] = frame->sample.reference_views.size();
  answer["cameras"] = std::move(cameras);
  return body(answer);
}

std::string Api::reference(const httplib::Request& req) {
  const auto [h, f] = person_frame(req);
  const auto frame = frames_.data(h, f);
  const int count = int(frame->sample.ref_images.size(0));
  const int i = int_param(req, "index", 0, count - 1);
  return png(frame->sample.ref_images[i].permute({1, 2, 0}));
}

std::string Api::evaluate(const httplib::Request& req, const std::function<bool()>& client_gone) {
  const auto [h, f] = person_frame(req);
  const int c = int_param(req, "camera", 0, session_.human(h).num_cameras() - 1);
  const auto hold = renderer_.take([&] { return stopped_or_gone(client_gone); });
  const auto r = session_.evaluate_view(h, f, c);
  Json answer;
  answer["human"] = session_.human(h).name();
  answer["frame"] = f;
  answer["view"] = c;
  answer["psnr"] = r.psnr;
  answer["ssim"] = r.ssim;
  return body(answer);
}

std::string Api::ground_truth(const httplib::Request& req) {
  const auto [h, f] = person_frame(req);
  const int c = int_param(req, "camera", 0, session_.human(h).num_cameras() - 1);
  const auto sample = session_.dataset().load_item({h, f, c}, 0);
  return png(sample.target_image * sample.box_mask.unsqueeze(-1).to(torch::kFloat32));
}

Api::View Api::render(const httplib::Request& req, const std::function<bool()>& client_gone) {
  const auto [h, f] = person_frame(req);
  // camera=C: dataset camera C exactly (K, R, T and image size), as transhuman-render --camera.
  const int snap = req.has_param("camera")
                       ? int_param(req, "camera", 0, session_.human(h).num_cameras() - 1)
                       : -1;
  const int width = snap >= 0 ? 0 : int_param(req, "width", 8, options_.max_size);
  const int height = snap >= 0 ? 0 : int_param(req, "height", 8, options_.max_size);
  const int samples = req.has_param("samples") ? int_param(req, "samples", 2, kMaxSamples) : 0;
  const std::string mode = req.has_param("mode") ? req.get_param_value("mode") : "rgb";
  if (mode != "rgb" && mode != "depth" && mode != "acc")
    throw BadRequest{"'mode' = '" + mode + "' must be rgb, depth or acc"};
  const std::string format = req.has_param("format") ? req.get_param_value("format") : "png";
  if (format != "png" && format != "jpeg")
    throw BadRequest{"'format' = '" + format + "' must be png or jpeg"};
  const bool baked = req.has_param("baked") && int_param(req, "baked", 0, 1) == 1;
  if (baked && snap >= 0)
    throw BadRequest{"'baked' views take eye..height, not 'camera' (a snap renders exactly)"};
  video::PathCamera camera;
  if (snap < 0) {
    const double fovy = number("fovy", param(req, "fovy"));
    if (!(fovy >= 1 && fovy <= 170))
      throw BadRequest{"'fovy' = " + param(req, "fovy") + " must be in [1, 170] degrees"};
    camera = look_camera(vec3(req, "eye", 1e4), vec3(req, "forward", 1e4), vec3(req, "up", 1e4),
                         fovy, width, height);
  }
  // Each page (client=ID) numbers its requests; a newer one cancels that page's older ones.
  const std::string client = req.has_param("client") ? req.get_param_value("client") : "";
  if (client.size() > 64) throw BadRequest{"'client' is longer than 64 characters"};
  const uint64_t seq = req.has_param("seq") ? uint64_t(int_param(req, "seq", 0, INT32_MAX)) : 0;
  {
    std::lock_guard<std::mutex> lock(latest_mutex_);
    if (latest_.size() > 1024 && !latest_.count(client)) latest_.clear();
    uint64_t& latest = latest_[client];
    latest = std::max(latest, seq);
  }
  const Interruption interrupted = [this, client, seq, &client_gone]() -> std::optional<HttpError> {
    if (auto e = stopped_or_gone(client_gone)) return e;
    std::lock_guard<std::mutex> lock(latest_mutex_);
    const auto it = latest_.find(client);
    if (it != latest_.end() && seq < it->second)
      return HttpError{409, "cancelled by a newer request"};
    return std::nullopt;
  };
  if (baked) return baked_view(h, f, camera, width, height, samples, mode, format, interrupted);

  const auto hold = renderer_.take(interrupted);
  const auto started = Clock::now();
  const auto prepared = frames_.prepared(h, f);
  int w = width, hh = height;
  if (snap >= 0) {
    camera = session_.dataset_camera(*prepared, snap);
    w = int(prepared->sample.target_image.size(1));
    hh = int(prepared->sample.target_image.size(0));
  }
  inference::Session::ViewControl control;
  control.samples = samples;
  const int per_ray = samples > 0 ? samples : session_.config().render.samples;
  control.band_pixels = std::max<int64_t>(1, kBandSamples / std::max(per_ray, 1));
  std::optional<HttpError> stopped;
  control.cancelled = [&] {
    stopped = interrupted();
    if (!stopped) stopped = past_time_bound(started, options_.render_timeout_s, "render");
    return bool(stopped);
  };
  const auto images = session_.render_view(*prepared, camera, w, hh, control);
  if (!images) {
    if (client_gone()) spdlog::info("viewer: a render was cancelled, its client went away");
    throw *stopped;
  }
  return encoded("render", started, display(images->rgb, images->depth, images->acc, mode), format);
}

Api::View Api::baked_view(int h, int f, const video::PathCamera& camera, int width, int height,
                          int samples, const std::string& mode, const std::string& format,
                          const Interruption& interrupted) {
  // A newer request of the same page (seq) stops this march as it stops an exact render.
  const auto frame = bakes_.ready(h, f);
  if (!frame)
    throw HttpError{404, "frame " + std::to_string(f) + " of person " + std::to_string(h) +
                             " is not baked (GET /api/bake starts its bake)"};
  const auto slot = baked_views_.try_take();
  if (!slot)
    throw HttpError{503,
                    "busy: " + std::to_string(kBakedViews) +
                        " baked views are being marched, the most the viewer runs at once",
                    1};
  bake::MarchOptions march;
  march.samples = samples > 0 ? samples : session_.config().render.samples;
  march.termination = session_.config().render.termination_transmittance;
  const auto started = Clock::now();
  std::optional<HttpError> stopped;
  const auto img =
      bake::render_baked(*frame, camera.K, camera.R, camera.T, width, height, march, [&] {
        stopped = interrupted();
        if (!stopped) stopped = past_time_bound(started, options_.render_timeout_s, "baked view");
        return bool(stopped);
      });
  if (!img) {
    if (stopped->status == 499)
      spdlog::info("viewer: a baked view was cancelled, its client went away");
    throw *stopped;
  }
  return encoded("march", started, display(img->rgb, img->depth, img->acc, mode), format);
}

std::string Api::bake_json(const httplib::Request& req) {
  const auto [h, f] = person_frame(req);
  if (!options_.bake) throw HttpError{404, "baking is off (transhuman-view --no-bake)"};
  const BakeStatus status = bakes_.ask(h, f);
  Json answer;
  // A bake waiting for its turn is "baking" too, so that a client polling while it is "baking"
  // waits for it; "waiting" tells the two apart.
  answer["state"] = status.state == "queued" ? "baking" : status.state;
  answer["waiting"] = status.state == "queued";
  answer["progress"] = status.progress;
  answer["voxel"] = options_.bake_voxel;
  answer["queued"] = status.queued;
  answer["dropped"] = status.dropped;
  if (status.state == "ready") {
    answer["seconds"] = status.seconds;
    answer["bricks"] = status.baked->stored_bricks();
    answer["mib"] = double(status.baked->bytes()) / 1048576.0;
  }
  if (status.state == "failed") answer["error"] = status.error;
  return body(answer);
}

std::pair<int, int> Api::person_frame(const httplib::Request& req) const {
  const int count = int(session_.dataset().humans().size());
  const int h = int_param(req, "human", 0, count - 1);
  const int f = int_param(req, "frame", 0, session_.human(h).num_frames() - 1);
  return {h, f};
}

std::optional<HttpError> Api::stopped_or_gone(const std::function<bool()>& client_gone) const {
  if (stopping_.load()) return HttpError{503, "the viewer is stopping"};
  if (client_gone()) return HttpError{499, "the client went away"};
  return std::nullopt;
}

}  // namespace th::viewer
