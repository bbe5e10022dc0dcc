#include "viewer/server.hpp"

#include <httplib.h>
#include <spdlog/spdlog.h>
#include <torch/torch.h>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include <cmath>
#include <fstream>
#include <map>
#include <mutex>
#include <sstream>

#include "core/error.hpp"
#include "report/report.hpp"
#include "viewer/page.hpp"

namespace th::viewer {
namespace fs = std::filesystem;
using inference::PreparedFrame;
using inference::Session;

namespace {

// A request parameter that is not what it must be: answered with 400 and this message.
struct BadRequest {
  std::string message;
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
  if (text.empty() || used != text.size()) throw BadRequest{"'" + name + "' = '" + text + "' is not an integer"};
  if (v < lo || v > hi)
    throw BadRequest{"'" + name + "' = " + text + " must be in [" + std::to_string(lo) + ", " + std::to_string(hi) + "]"};
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
  if (v.size() != 3) throw BadRequest{"'" + name + "' = '" + text + "' must be three numbers x,y,z"};
  for (double x : v)
    if (std::abs(x) > max_abs) throw BadRequest{"'" + name + "' = '" + text + "' is farther than " +
                                                std::to_string(int(max_abs)) + " from the origin"};
  return torch::tensor(v, torch::kFloat64);
}

// The pinhole camera at `eye` looking along `forward` with `up` roughly up, vertical field of
// view `fovy` degrees, for a width x height image: OpenCV axes (x right, y down, z forward).
th::video::PathCamera look_camera(const torch::Tensor& eye, const torch::Tensor& forward, const torch::Tensor& up,
                                  double fovy, int width, int height) {
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
                               torch::kFloat64).reshape({3, 3});
  return {K, R, T};
}

std::string json_vec(const torch::Tensor& v) {
  const auto c = v.to(torch::kFloat64).contiguous();
  std::ostringstream out;
  out.precision(9);
  out << '[' << c[0].item<double>() << ',' << c[1].item<double>() << ',' << c[2].item<double>() << ']';
  return out.str();
}

// (H, W, 3) float RGB in [0, 1], or (H, W) values in [0, 1] shown as grey, as PNG bytes.
std::string png(const torch::Tensor& image) {
  auto u8 = (image.clamp(0, 1) * 255).round().to(torch::kUInt8).contiguous();
  const int h = int(u8.size(0)), w = int(u8.size(1)), c = u8.dim() == 3 ? 3 : 1;
  cv::Mat m(h, w, c == 3 ? CV_8UC3 : CV_8UC1, u8.data_ptr<uint8_t>());
  cv::Mat out;
  if (c == 3) cv::cvtColor(m, out, cv::COLOR_RGB2BGR);
  else out = m;
  std::vector<uchar> bytes;
  cv::imencode(".png", out, bytes);
  return std::string(bytes.begin(), bytes.end());
}

class Viewer {
 public:
  Viewer(const Session& session, int view, int max_size, int start_human, int start_frame)
      : session_(session), view_(view), max_size_(max_size), start_human_(start_human), start_frame_(start_frame) {}

  std::string info() const {
    std::ostringstream out;
    out << "{\"humans\":[";
    for (size_t h = 0; h < session_.dataset().humans().size(); ++h) {
      const auto& person = session_.human(int(h));
      out << (h ? "," : "") << "{\"name\":" << report::js_string(person.name()) << ",\"cameras\":" << person.num_cameras()
          << ",\"frames\":[";
      const auto frames = session_.setting_frames(int(h));
      for (size_t i = 0; i < frames.size(); ++i) out << (i ? "," : "") << frames[i];
      out << "]}";
    }
    const auto& c = session_.config();
    out << "],\"samples\":" << c.render.samples << ",\"max_size\":" << max_size_ << ",\"view\":" << view_
        << ",\"max_samples\":4096,\"start\":{\"human\":" << start_human_ << ",\"frame\":" << start_frame_ << "}}";
    return out.str();
  }

  std::string frame_json(const httplib::Request& req) {
    const auto [h, f] = person_frame(req);
    std::lock_guard<std::mutex> lock(prepare_mutex_);
    const PreparedFrame& prepared = prepared_frame(h, f);
    std::ostringstream out;
    out << "{\"center\":" << json_vec(session_.body_center(h, f)) << ",\"references\":"
        << prepared.sample.reference_views.size() << ",\"cameras\":[";
    for (int c = 0; c < session_.human(h).num_cameras(); ++c) {
      const auto cam = session_.dataset_camera(prepared, c);
      const auto R = cam.R, eye = -torch::mv(R.t(), cam.T.flatten());
      const double height = double(prepared.sample.target_image.size(0));
      const double fy = cam.K[1][1].item<double>();
      out << (c ? "," : "") << "{\"eye\":" << json_vec(eye) << ",\"forward\":" << json_vec(R[2])
          << ",\"up\":" << json_vec(-R[1]) << ",\"fovy\":" << 2.0 * std::atan(0.5 * height / fy) * 180.0 / M_PI
          << ",\"width\":" << prepared.sample.target_image.size(1) << ",\"height\":" << height << "}";
    }
    out << "]}";
    return out.str();
  }

  std::string reference(const httplib::Request& req) {
    const auto [h, f] = person_frame(req);
    std::lock_guard<std::mutex> lock(prepare_mutex_);
    const PreparedFrame& prepared = prepared_frame(h, f);
    const int count = int(prepared.sample.ref_images.size(0));
    const int i = int_param(req, "index", 0, count - 1);
    return png(prepared.sample.ref_images[i].permute({1, 2, 0}));
  }

  // Dataset camera C of a frame scored as transhuman-eval scores it, with its ground truth.
  std::string evaluate(const httplib::Request& req) {
    const auto [h, f] = person_frame(req);
    const int c = int_param(req, "camera", 0, session_.human(h).num_cameras() - 1);
    std::unique_lock<std::timed_mutex> lock(render_mutex_, std::defer_lock);
    if (!lock.try_lock_for(std::chrono::seconds(60))) throw BadRequest{"busy: another render has run for a minute"};
    const auto r = session_.evaluate_view(h, f, c);
    std::ostringstream out;
    out.precision(10);
    out << "{\"human\":" << report::js_string(session_.human(h).name()) << ",\"frame\":" << f << ",\"view\":" << c
        << ",\"psnr\":" << r.psnr << ",\"ssim\":" << r.ssim << "}";
    return out.str();
  }

  // The ground truth of dataset camera C (the target image inside the body's box), PNG.
  std::string ground_truth(const httplib::Request& req) {
    const auto [h, f] = person_frame(req);
    const int c = int_param(req, "camera", 0, session_.human(h).num_cameras() - 1);
    const auto sample = session_.dataset().load_item({h, f, c}, 0);
    return png(sample.target_image * sample.box_mask.unsqueeze(-1).to(torch::kFloat32));
  }

  // nullopt: cancelled by a newer request.
  std::optional<std::string> render(const httplib::Request& req) {
    const auto [h, f] = person_frame(req);
    // camera=C: dataset camera C exactly (K, R, T and image size), as transhuman-render --camera.
    const int snap = req.has_param("camera") ? int_param(req, "camera", 0, session_.human(h).num_cameras() - 1) : -1;
    const int width = snap >= 0 ? 0 : int_param(req, "width", 8, max_size_);
    const int height = snap >= 0 ? 0 : int_param(req, "height", 8, max_size_);
    const int samples = req.has_param("samples") ? int_param(req, "samples", 2, 4096) : 0;
    const std::string mode = req.has_param("mode") ? req.get_param_value("mode") : "rgb";
    if (mode != "rgb" && mode != "depth" && mode != "acc")
      throw BadRequest{"'mode' = '" + mode + "' must be rgb, depth or acc"};
    th::video::PathCamera camera;
    if (snap < 0) {
      const double fovy = number("fovy", param(req, "fovy"));
      if (!(fovy >= 1 && fovy <= 170)) throw BadRequest{"'fovy' = " + param(req, "fovy") + " must be in [1, 170] degrees"};
      camera = look_camera(vec3(req, "eye", 1e4), vec3(req, "forward", 1e4), vec3(req, "up", 1e4), fovy, width, height);
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
    const auto stale = [this, client, seq] {
      std::lock_guard<std::mutex> lock(latest_mutex_);
      const auto it = latest_.find(client);
      return it != latest_.end() && seq < it->second;
    };
    // One render at a time, bounded waiting.
    std::unique_lock<std::timed_mutex> lock(render_mutex_, std::defer_lock);
    if (!lock.try_lock_for(std::chrono::seconds(60))) throw BadRequest{"busy: another render has run for a minute"};
    if (stale()) return std::nullopt;
    std::lock_guard<std::mutex> prep(prepare_mutex_);
    const PreparedFrame& prepared = prepared_frame(h, f);
    int w = width, hh = height;
    if (snap >= 0) {
      camera = session_.dataset_camera(prepared, snap);
      w = int(prepared.sample.target_image.size(1));
      hh = int(prepared.sample.target_image.size(0));
    }
    Session::ViewControl control;
    control.samples = samples;
    control.band_pixels = 4096;  // cancellation is polled between bands
    control.cancelled = stale;
    const auto images = session_.render_view(prepared, camera, w, hh, control);
    if (!images) return std::nullopt;
    if (mode == "rgb") return png(images->rgb);
    if (mode == "acc") return png(images->acc);
    const auto valid = images->acc > 1e-3;
    auto depth = images->depth.clone();
    if (valid.any().item<bool>()) {
      const auto d = depth.index({valid});
      const double lo = d.min().item<double>(), hi = d.max().item<double>();
      depth = torch::where(valid, 1.0 - (depth - lo) / std::max(hi - lo, 1e-6) * 0.8, torch::zeros_like(depth));
    }
    return png(depth);
  }

 private:
  std::pair<int, int> person_frame(const httplib::Request& req) const {
    const int count = int(session_.dataset().humans().size());
    const int h = int_param(req, "human", 0, count - 1);
    const int f = int_param(req, "frame", 0, session_.human(h).num_frames() - 1);
    return {h, f};
  }

  // The frame cache: preparing a frame (encoder, tokens) is paid once per frame shown.
  const PreparedFrame& prepared_frame(int h, int f) {
    const auto key = std::make_pair(h, f);
    auto it = prepared_.find(key);
    if (it == prepared_.end()) {
      if (prepared_.size() >= 4) prepared_.erase(prepared_.begin());
      it = prepared_.emplace(key, session_.prepare(h, f, view_)).first;
    }
    return it->second;
  }

  const Session& session_;
  int view_, max_size_, start_human_, start_frame_;
  std::map<std::pair<int, int>, PreparedFrame> prepared_;
  std::mutex prepare_mutex_;
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
  Impl(const Session& session, const Options& o)
      : options(o), viewer(session, o.view, o.max_size, o.start_human, o.start_frame) {}
  Options options;
  Viewer viewer;
  httplib::Server server;
};

Server::Server(const Session& session, const Options& options) : impl_(std::make_unique<Impl>(session, options)) {
  httplib::Server& server = impl_->server;
  Viewer& viewer = impl_->viewer;
  const fs::path three = th::report::find_three_js();
    const auto guarded = [](const std::function<void(const httplib::Request&, httplib::Response&)>& fn) {
      return [fn](const httplib::Request& req, httplib::Response& res) {
        try {
          fn(req, res);
        } catch (const BadRequest& e) {
          res.status = 400;
          res.set_content(e.message + "\n", "text/plain");
        } catch (const th::Error& e) {
          res.status = 400;
          res.set_content(std::string(e.what()) + "\n", "text/plain");
        } catch (const std::exception& e) {
          spdlog::error("viewer: {}", e.what());
          res.status = 500;
          res.set_content(std::string("internal error: ") + e.what() + "\n", "text/plain");
        }
      };
    };
    server.Get("/", guarded([](const httplib::Request&, httplib::Response& res) {
      res.set_content(kPage, "text/html; charset=utf-8");
    }));
    for (const char* name : {"three.min.js", "OrbitControls.js"}) {
      const std::string file = name;
      server.Get("/three/" + file, guarded([three, file](const httplib::Request&, httplib::Response& res) {
        const fs::path path = file == "three.min.js" ? three / "build" / file
                                                     : three / "examples" / "js" / "controls" / file;
        if (three.empty() || !fs::is_regular_file(path)) {
          res.status = 404;
          res.set_content("three.js not found (Debian: apt-get install libjs-three)\n", "text/plain");
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
    server.Get("/api/reference", guarded([&viewer](const httplib::Request& req, httplib::Response& res) {
      res.set_content(viewer.reference(req), "image/png");
    }));
    server.Get("/api/evaluate", guarded([&viewer](const httplib::Request& req, httplib::Response& res) {
      res.set_content(viewer.evaluate(req), "application/json");
    }));
    server.Get("/api/ground_truth", guarded([&viewer](const httplib::Request& req, httplib::Response& res) {
      res.set_content(viewer.ground_truth(req), "image/png");
    }));
    server.Get("/api/render", guarded([&viewer](const httplib::Request& req, httplib::Response& res) {
      const auto image = viewer.render(req);
      if (!image) {
        res.status = 409;
        res.set_content("cancelled by a newer request\n", "text/plain");
        return;
      }
      res.set_header("Cache-Control", "no-store");
      res.set_content(*image, "image/png");
    }));

  if (!server.bind_to_port(options.host.c_str(), options.port))
    fail("cannot listen on ", options.host, ":", options.port, " (in use? try another --port)");
  if (options.host != "127.0.0.1" && options.host != "localhost" && options.host != "::1")
    spdlog::warn("LISTENING ON {}:{}: anyone who can reach this address can use the viewer", options.host,
                 options.port);
}

Server::~Server() = default;

std::string Server::url() const {
  const auto& o = impl_->options;
  return "http://" + (o.host == "0.0.0.0" ? std::string("127.0.0.1") : o.host) + ":" + std::to_string(o.port) + "/";
}

void Server::run() { impl_->server.listen_after_bind(); }

void Server::stop() { impl_->server.stop(); }

}  // namespace th::viewer
