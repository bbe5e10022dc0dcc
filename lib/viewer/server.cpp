#include "viewer/server.hpp"

#include <arpa/inet.h>
#include <httplib.h>
#include <netinet/in.h>
#include <spdlog/spdlog.h>
#include <torch/torch.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <fstream>
#include <functional>
#include <map>
#include <mutex>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <optional>
#include <sstream>
#include <thread>

#include "bake/bake.hpp"
#include "core/error.hpp"
#include "report/report.hpp"
#include "viewer/access.hpp"
#include "viewer/listener.hpp"
#include "viewer/page.hpp"
#include "viewer/recent.hpp"

namespace th::viewer {
namespace fs = std::filesystem;
using inference::PreparedFrame;
using inference::Session;

namespace {

using Clock = std::chrono::steady_clock;

// A request answered with an error: its status, a message naming the cause, and Retry-After
// seconds when trying again later may succeed.
struct HttpError {
  int status = 500;
  std::string message;
  int retry_after_s = 0;
};

// A request parameter that is not what it must be: answered with 400 and this message.
struct BadRequest : HttpError {
  explicit BadRequest(std::string text) : HttpError{400, std::move(text)} {}
};

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

// The pinhole camera at `eye` looking along `forward` with `up` roughly up, vertical field of
// view `fovy` degrees, for a width x height image: OpenCV axes (x right, y down, z forward).
th::video::PathCamera look_camera(const torch::Tensor& eye, const torch::Tensor& forward,
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

using Json = nlohmann::ordered_json;

// An answer's body: bytes of a name that are not UTF-8 become U+FFFD, and a NaN or infinite
// score is written as null (JSON has neither).
std::string body(const Json& answer) {
  return answer.dump(-1, ' ', false, Json::error_handler_t::replace);
}

// A 3-vector: [x, y, z].
Json vec3_json(const torch::Tensor& v) {
  const auto c = v.to(torch::kFloat64).contiguous();
  return Json::array({c[0].item<double>(), c[1].item<double>(), c[2].item<double>()});
}

// (H, W, 3) float RGB in [0, 1], or (H, W) values in [0, 1] shown as grey, as PNG bytes (or
// JPEG at quality 90 with `jpeg`: a few times faster to make, for views shown while moving).
// Each value becomes the nearest of 256 levels as transhuman-render's images do (x 255, rounded
// half to even, clamped; NaN black), in one pass that also turns RGB into OpenCV's BGR.
std::string png(const torch::Tensor& image, bool jpeg = false) {
  const auto values = image.to(torch::kFloat32).contiguous();
  const int h = int(values.size(0)), w = int(values.size(1)), c = values.dim() == 3 ? 3 : 1;
  cv::Mat out(h, w, c == 3 ? CV_8UC3 : CV_8UC1);
  const float* in = values.data_ptr<float>();
  uint8_t* o = out.ptr<uint8_t>();
  const int64_t pixels = int64_t(h) * w;
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

// What a view shows: its colours, or depth (near light, far dark, black where nothing is) or
// accumulated opacity as grey.
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

// A frame's bake as the page sees it: under way (with its progress), ready, or failed.
struct BakeState {
  std::string state = "baking";  // baking | ready | failed
  double progress = 0, seconds = 0;
  std::string error;
  std::shared_ptr<const bake::BakedFrame> baked;
};

// Why a render or a wait for the renderer ends early: nullopt while it may go on.
using Interruption = std::function<std::optional<HttpError>()>;

class Viewer {
 public:
  Viewer(const Session& session, const Options& options, const std::atomic<bool>& stopping)
      : session_(session), options_(options), stopping_(stopping) {
    bake_options_.voxel = options.bake_voxel;
    bake::check_options(bake_options_);
  }
  ~Viewer() {
    for (auto& t : bakers_) t.join();  // they end soon once the viewer stops
  }

  std::string info() const {
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
    answer["start"] = {{"human", options_.start_human}, {"frame", options_.start_frame}};
    return body(answer);
  }

  // Data only (no network): answers while a render runs.
  std::string frame_json(const httplib::Request& req) {
    const auto [h, f] = person_frame(req);
    const auto frame = frame_data(h, f);
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

  std::string reference(const httplib::Request& req) {
    const auto [h, f] = person_frame(req);
    const auto frame = frame_data(h, f);
    const int count = int(frame->sample.ref_images.size(0));
    const int i = int_param(req, "index", 0, count - 1);
    return png(frame->sample.ref_images[i].permute({1, 2, 0}));
  }

  // Dataset camera C of a frame scored as transhuman-eval scores it, with its ground truth.
  std::string evaluate(const httplib::Request& req, const std::function<bool()>& client_gone) {
    const auto [h, f] = person_frame(req);
    const int c = int_param(req, "camera", 0, session_.human(h).num_cameras() - 1);
    const auto lock = render_lock([&] { return stopped_or_gone(client_gone); });
    const auto r = session_.evaluate_view(h, f, c);
    Json answer;
    answer["human"] = session_.human(h).name();
    answer["frame"] = f;
    answer["view"] = c;
    answer["psnr"] = r.psnr;
    answer["ssim"] = r.ssim;
    return body(answer);
  }

  // The ground truth of dataset camera C (the target image inside the body's box), PNG.
  std::string ground_truth(const httplib::Request& req) {
    const auto [h, f] = person_frame(req);
    const int c = int_param(req, "camera", 0, session_.human(h).num_cameras() - 1);
    const auto sample = session_.dataset().load_item({h, f, c}, 0);
    return png(sample.target_image * sample.box_mask.unsqueeze(-1).to(torch::kFloat32));
  }

  // A view's image, and how long its stages took as an HTTP Server-Timing header's value
  // (milliseconds: `march` or `render`, then `encode`), so a page or benchmark can tell the
  // server's part of a round trip from the rest.
  struct View {
    std::string bytes;
    std::string timing;
  };

  // A PNG, or HttpError: 409 when a newer request of the same page took over, 503 when the
  // viewer stops, the render runs past its time bound or the renderer stays busy.
  View render(const httplib::Request& req, const std::function<bool()>& client_gone) {
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
    th::video::PathCamera camera;
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
    const Interruption interrupted = [this, client, seq,
                                      &client_gone]() -> std::optional<HttpError> {
      if (auto e = stopped_or_gone(client_gone)) return e;
      std::lock_guard<std::mutex> lock(latest_mutex_);
      const auto it = latest_.find(client);
      if (it != latest_.end() && seq < it->second)
        return HttpError{409, "cancelled by a newer request"};
      return std::nullopt;
    };
    if (baked) {
      // From the frame's bake: no network, so no wait for the renderer; a newer request of the
      // same page (seq above) already tells an exact render in flight to stop.
      const auto frame = baked_frame(h, f);
      if (!frame)
        throw HttpError{404, "frame " + std::to_string(f) + " of person " + std::to_string(h) +
                                 " is not baked (GET /api/bake starts its bake)"};
      bake::MarchOptions march;
      march.samples = samples > 0 ? samples : session_.config().render.samples;
      march.termination = session_.config().render.termination_transmittance;
      const auto marched = Clock::now();
      const auto img =
          bake::render_baked(*frame, camera.K, camera.R, camera.T, width, height, march);
      return encoded("march", marched, display(img.rgb, img.depth, img.acc, mode), format);
    }
    const auto lock = render_lock(interrupted);
    const auto started = Clock::now();
    const auto prepared = prepared_frame(h, f);
    int w = width, hh = height;
    if (snap >= 0) {
      camera = session_.dataset_camera(*prepared, snap);
      w = int(prepared->sample.target_image.size(1));
      hh = int(prepared->sample.target_image.size(0));
    }
    Session::ViewControl control;
    control.samples = samples;
    // Cancellation is polled between bands: about kBandSamples samples each (whole rows).
    const int per_ray = samples > 0 ? samples : session_.config().render.samples;
    control.band_pixels = std::max<int64_t>(1, kBandSamples / std::max(per_ray, 1));
    std::optional<HttpError> stopped;
    control.cancelled = [&] {
      stopped = interrupted();
      if (!stopped && Clock::now() - started > std::chrono::seconds(options_.render_timeout_s))
        stopped = HttpError{
            503, "the render ran past the viewer's bound of " +
                     std::to_string(options_.render_timeout_s) +
                     " s per render (--render-timeout) and was stopped: ask for fewer samples "
                     "or a smaller image"};
      return bool(stopped);
    };
    const auto images = session_.render_view(*prepared, camera, w, hh, control);
    if (!images) {
      if (client_gone()) spdlog::info("viewer: a render was cancelled, its client went away");
      throw *stopped;
    }
    return encoded("render", started, display(images->rgb, images->depth, images->acc, mode),
                   format);
  }

  // The view's bytes in `format`, with the time since `started` as the stage `stage`.
  static View encoded(const char* stage, Clock::time_point started, const torch::Tensor& image,
                      const std::string& format) {
    const auto ms = [](Clock::duration d) {
      return std::chrono::duration<double, std::milli>(d).count();
    };
    const auto encoding = Clock::now();
    View view{png(image, format == "jpeg"), ""};
    view.timing = fmt::format("{};dur={:.1f}, encode;dur={:.1f}", stage, ms(encoding - started),
                              ms(Clock::now() - encoding));
    return view;
  }

  // The bake of a frame: started in the background when first asked for (with --bake), then its
  // progress, until it is ready or failed.
  std::string bake_json(const httplib::Request& req) {
    const auto [h, f] = person_frame(req);
    if (!options_.bake) throw HttpError{404, "baking is off (transhuman-view --no-bake)"};
    std::shared_ptr<BakeState> state;
    {
      std::lock_guard<std::mutex> lock(bakes_mutex_);
      if (auto* found = bakes_.find({h, f})) {
        state = *found;
      } else {
        state = bakes_.put({h, f}, std::make_shared<BakeState>());
        bakers_.emplace_back([this, h = h, f = f, state] { run_bake(h, f, state); });
      }
    }
    Json answer;
    std::lock_guard<std::mutex> lock(bakes_mutex_);
    answer["state"] = state->state;
    answer["progress"] = state->progress;
    answer["voxel"] = options_.bake_voxel;
    if (state->state == "ready") {
      answer["seconds"] = state->seconds;
      answer["bricks"] = state->baked->stored_bricks();
      answer["mib"] = double(state->baked->bytes()) / 1048576.0;
    }
    if (state->state == "failed") answer["error"] = state->error;
    return body(answer);
  }

 private:
  static constexpr int kMaxSamples = 4096;
  static constexpr int64_t kBandSamples = int64_t{1} << 18;

  std::pair<int, int> person_frame(const httplib::Request& req) const {
    const int count = int(session_.dataset().humans().size());
    const int h = int_param(req, "human", 0, count - 1);
    const int f = int_param(req, "frame", 0, session_.human(h).num_frames() - 1);
    return {h, f};
  }

  std::optional<HttpError> stopped_or_gone(const std::function<bool()>& client_gone) const {
    if (stopping_.load()) return HttpError{503, "the viewer is stopping"};
    if (client_gone()) return HttpError{499, "the client went away"};
    return std::nullopt;
  }

  // The renderer, one request at a time (the network runs for one request at a time). Waits
  // while `interrupted` says nothing, at most as long as a render may run; then 503.
  std::unique_lock<std::timed_mutex> render_lock(const Interruption& interrupted) {
    std::unique_lock<std::timed_mutex> lock(render_mutex_, std::defer_lock);
    const auto until = Clock::now() + std::chrono::seconds(options_.render_timeout_s + 5);
    while (!lock.try_lock_for(std::chrono::milliseconds(50))) {
      if (auto e = interrupted()) throw *e;
      if (Clock::now() > until)
        throw HttpError{503,
                        "busy: another request has had the renderer for " +
                            std::to_string(options_.render_timeout_s + 5) + " s",
                        2};
    }
    if (auto e = interrupted()) throw *e;
    return lock;
  }

  // A frame's data (reference views, target image size), without the network; kept for the
  // last few frames asked for.
  std::shared_ptr<const PreparedFrame> frame_data(int h, int f) {
    const auto key = std::make_pair(h, f);
    {
      std::lock_guard<std::mutex> lock(frames_mutex_);
      if (const auto* found = data_.find(key)) return *found;
    }
    auto frame = std::make_shared<PreparedFrame>();
    frame->human = h;
    frame->frame = f;
    frame->sample = session_.dataset().load_item({h, f, options_.view}, 0);
    std::lock_guard<std::mutex> lock(frames_mutex_);
    return data_.put(key, std::move(frame));
  }

  // The frame cache: preparing a frame (encoder, tokens) is paid once per frame shown. Called
  // with the renderer held.
  std::shared_ptr<const PreparedFrame> prepared_frame(int h, int f) {
    const auto key = std::make_pair(h, f);
    if (const auto* found = prepared_.find(key)) return *found;
    return prepared_.put(
        key, std::make_shared<const PreparedFrame>(session_.prepare(h, f, options_.view)));
  }

  // The frame's bake when it is ready, else null.
  std::shared_ptr<const bake::BakedFrame> baked_frame(int h, int f) {
    std::lock_guard<std::mutex> lock(bakes_mutex_);
    const auto* found = bakes_.find({h, f});
    return found && (*found)->state == "ready" ? (*found)->baked : nullptr;
  }

  // A bake in the background: it waits for the renderer (the network runs for one request at
  // a time) and holds it while it runs; exact requests wait behind it as behind a render.
  void run_bake(int h, int f, const std::shared_ptr<BakeState>& state) {
    const auto started = Clock::now();
    auto finish = [&](const std::string& outcome, const std::string& error,
                      std::shared_ptr<const bake::BakedFrame> baked) {
      std::lock_guard<std::mutex> lock(bakes_mutex_);
      state->state = outcome;
      state->error = error;
      state->baked = std::move(baked);
      state->seconds = std::chrono::duration<double>(Clock::now() - started).count();
    };
    try {
      std::unique_lock<std::timed_mutex> lock(render_mutex_, std::defer_lock);
      while (!lock.try_lock_for(std::chrono::milliseconds(50)))
        if (stopping_.load()) return finish("failed", "the viewer is stopping", nullptr);
      const auto prepared = prepared_frame(h, f);
      auto baked = bake::bake_frame(session_, *prepared, bake_options_, nullptr, [&](double p) {
        if (stopping_.load()) throw HttpError{503, "the viewer is stopping"};
        std::lock_guard<std::mutex> guard(bakes_mutex_);
        state->progress = p;
      });
      spdlog::info("viewer: baked {} frame {} in {:.1f} s ({} bricks, {:.1f} MiB)", baked.human,
                   baked.frame, std::chrono::duration<double>(Clock::now() - started).count(),
                   baked.stored_bricks(), double(baked.bytes()) / 1048576.0);
      finish("ready", "", std::make_shared<const bake::BakedFrame>(std::move(baked)));
    } catch (const HttpError& e) {
      finish("failed", e.message, nullptr);
    } catch (const std::exception& e) {
      spdlog::error("viewer: the bake of person {} frame {} failed: {}", h, f, e.what());
      finish("failed", e.what(), nullptr);
    }
  }

  const Session& session_;
  const Options options_;
  const std::atomic<bool>& stopping_;
  bake::BakeOptions bake_options_;
  using FrameKey = std::pair<int, int>;                                 // person, frame
  Recent<FrameKey, std::shared_ptr<const PreparedFrame>> prepared_{4};  // with render_mutex_
  Recent<FrameKey, std::shared_ptr<const PreparedFrame>> data_{8};      // with frames_mutex_
  std::mutex frames_mutex_;
  Recent<FrameKey, std::shared_ptr<BakeState>> bakes_{4};  // with bakes_mutex_
  std::mutex bakes_mutex_;
  std::vector<std::thread> bakers_;  // with bakes_mutex_; joined at the end
  std::timed_mutex render_mutex_;
  std::map<std::string, uint64_t> latest_;  // per client: the newest request seen
  std::mutex latest_mutex_;
};

std::string read_file(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

}  // namespace

struct Server::Impl {
  Impl(const Session& session, const Options& o) : options(o), viewer(session, o, stopping) {}
  ~Impl() { stopping = true; }  // background bakes end before the viewer goes
  Options options;
  std::atomic<bool> stopping{false};
  Viewer viewer;
  Listener server;
  std::unique_ptr<Access> access;  // once bound
};

Server::Server(const Session& session, const Options& options)
    : impl_(std::make_unique<Impl>(session, options)) {
  Listener& server = impl_->server;
  Viewer& viewer = impl_->viewer;
  const fs::path three = th::report::find_three_js();
  const auto answer = [](httplib::Response& res, int status, const std::string& message) {
    res.status = status;
    res.set_header("Cache-Control", "no-store");
    res.set_content(message.empty() || message.back() != '\n' ? message + "\n" : message,
                    "text/plain; charset=utf-8");
  };
  const auto guarded =
      [answer](const std::function<void(const httplib::Request&, httplib::Response&)>& fn) {
        return [fn, answer](const httplib::Request& req, httplib::Response& res) {
          try {
            fn(req, res);
          } catch (const HttpError& e) {
            answer(res, e.status, e.message);
            if (e.retry_after_s > 0) res.set_header("Retry-After", std::to_string(e.retry_after_s));
          } catch (const th::Error& e) {
            answer(res, 400, e.what());
          } catch (const std::exception& e) {
            spdlog::error("viewer: {}", e.what());
            answer(res, 500, std::string("internal error: ") + e.what());
          }
        };
      };
  // Who is answered at all (viewer/access.hpp), before any route and before a body is read.
  server.set_pre_routing_handler(
      [this, answer](const httplib::Request& req, httplib::Response& res) {
        const auto refusal = impl_->access->check(req);
        if (!refusal) return httplib::Server::HandlerResponse::Unhandled;
        Listener::close_after_response();
        answer(res, refusal->status, refusal->message);
        if (refusal->status == 405) res.set_header("Allow", "GET, HEAD");
        return httplib::Server::HandlerResponse::Handled;
      });
  // "Expect: 100-continue" is answered before routing: refused uploads are refused there too.
  server.set_expect_100_continue_handler(
      [this, answer](const httplib::Request& req, httplib::Response& res) {
        const auto refusal = impl_->access->check(req);
        if (!refusal) return 100;
        Listener::close_after_response();
        answer(res, refusal->status, refusal->message);
        return refusal->status;
      });
  server.Get("/", guarded([](const httplib::Request&, httplib::Response& res) {
               res.set_header("X-Frame-Options", "DENY");
               res.set_header("Content-Security-Policy", "frame-ancestors 'none'");
               res.set_content(kPage, "text/html; charset=utf-8");
             }));
  for (const char* name : {"three.min.js", "OrbitControls.js"}) {
    const std::string file = name;
    server.Get("/three/" + file,
               guarded([three, file](const httplib::Request&, httplib::Response& res) {
                 const fs::path path = file == "three.min.js"
                                           ? three / "build" / file
                                           : three / "examples" / "js" / "controls" / file;
                 if (three.empty() || !fs::is_regular_file(path)) {
                   res.status = 404;
                   res.set_content("three.js not found (Debian: apt-get install libjs-three)\n",
                                   "text/plain");
                   return;
                 }
                 res.set_content(read_file(path), "application/javascript");
               }));
  }
  server.Get("/api/info", guarded([&viewer](const httplib::Request&, httplib::Response& res) {
               res.set_content(viewer.info(), "application/json");
             }));
  server.Get("/api/frame", guarded([&viewer](const httplib::Request& req, httplib::Response& res) {
               res.set_content(viewer.frame_json(req), "application/json");
             }));
  server.Get("/api/reference",
             guarded([&viewer](const httplib::Request& req, httplib::Response& res) {
               res.set_content(viewer.reference(req), "image/png");
             }));
  server.Get("/api/evaluate",
             guarded([&viewer](const httplib::Request& req, httplib::Response& res) {
               res.set_content(viewer.evaluate(req, Listener::client_gone), "application/json");
             }));
  server.Get("/api/ground_truth",
             guarded([&viewer](const httplib::Request& req, httplib::Response& res) {
               res.set_content(viewer.ground_truth(req), "image/png");
             }));
  server.Get("/api/bake", guarded([&viewer](const httplib::Request& req, httplib::Response& res) {
               res.set_header("Cache-Control", "no-store");
               res.set_content(viewer.bake_json(req), "application/json");
             }));
  server.Get("/api/render", guarded([&viewer](const httplib::Request& req, httplib::Response& res) {
               const auto view = viewer.render(req, Listener::client_gone);
               res.set_header("Cache-Control", "no-store");
               res.set_header("Server-Timing", view.timing);
               const bool jpeg = req.has_param("format") && req.get_param_value("format") == "jpeg";
               res.set_content(view.bytes, jpeg ? "image/jpeg" : "image/png");
             }));

  // An empty --host means every interface, as it does for most servers (getaddrinfo would
  // take it for loopback).
  server.bind(options.host.empty() ? "0.0.0.0" : options.host, options.port);
  impl_->access = std::make_unique<Access>(options.host, server.bound_address(), options.port,
                                           options.allow_hosts);
  if (interfaces().find("only") == std::string::npos)
    spdlog::warn("LISTENING ON {}: anyone who can reach it can use the viewer", interfaces());
}

Server::~Server() = default;

namespace {

bool is_loopback(const sockaddr_storage& a) {
  if (a.ss_family == AF_INET)
    return (ntohl(reinterpret_cast<const sockaddr_in&>(a).sin_addr.s_addr) >> 24) == 127;
  return a.ss_family == AF_INET6 &&
         IN6_IS_ADDR_LOOPBACK(&reinterpret_cast<const sockaddr_in6&>(a).sin6_addr);
}

bool is_any(const sockaddr_storage& a) {
  if (a.ss_family == AF_INET)
    return reinterpret_cast<const sockaddr_in&>(a).sin_addr.s_addr == htonl(INADDR_ANY);
  return a.ss_family == AF_INET6 &&
         IN6_IS_ADDR_UNSPECIFIED(&reinterpret_cast<const sockaddr_in6&>(a).sin6_addr);
}

}  // namespace

std::string Server::url() const {
  const auto bound = impl_->server.bound_address();
  const std::string& host = impl_->options.host;
  in6_addr scratch{};
  const bool literal = host.empty() || ::inet_pton(AF_INET, host.c_str(), &scratch) == 1 ||
                       ::inet_pton(AF_INET6, host.c_str(), &scratch) == 1;
  std::string name;
  if (is_any(bound))
    name = impl_->server.ipv6_only() ? "[::1]" : "127.0.0.1";
  else if (literal)
    name = url_host(numeric_address(bound));
  else
    name = host;
  return "http://" + name + ":" + std::to_string(impl_->options.port) + "/";
}

std::string Server::interfaces() const {
  const auto bound = impl_->server.bound_address();
  const std::string address = url_host(numeric_address(bound));
  if (is_any(bound)) {
    const char* families = bound.ss_family == AF_INET  ? ", IPv4)"
                           : impl_->server.ipv6_only() ? ", IPv6)"
                                                       : ", IPv4 and IPv6)";
    return "every interface of this machine (" + address + families;
  }
  return address + (is_loopback(bound) ? " only (this machine)" : " (reachable from the network)");
}

std::string Server::host_names() const { return impl_->access->names(); }

void Server::run() {
  if (!impl_->stopping) impl_->server.listen_after_bind();
}

void Server::stop() {
  impl_->stopping = true;
  impl_->server.shut_down();
}

}  // namespace th::viewer
