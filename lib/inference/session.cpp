#include "inference/session.hpp"

#include <fmt/format.h>
#include <torch/torch.h>

#include <algorithm>

#include "body/smpl.hpp"
#include "core/error.hpp"
#include "data/rays.hpp"
#include "pipeline/checkpoint.hpp"
#include "pipeline/pipeline.hpp"
#include "render/chunks.hpp"

namespace th::inference {
namespace fs = std::filesystem;

Session::Session(const Config& config, const torch::Device& device, const fs::path& checkpoint)
    : config_(config), device_(device), checkpoint_(fs::absolute(checkpoint)) {
  const auto smpl = data::load_body_model(config.data);
  dataset_ = std::make_shared<const data::Dataset>(config.data, config.eval.setting,
                                                   data::Dataset::Mode::Test, smpl);
  canonical_ = smpl->v_template;  // float64: token positions [parity]
  model_ = model::TransHuman(config.model);
  pipeline::load_weights(*model_, checkpoint, config.eval.model_mismatch == MismatchPolicy::warn);
  tokens_ =
      std::make_unique<pipeline::Tokens>(*model_, smpl->v_template);  // the checkpoint's groups
  model_->to(device);
  model_->eval();
  model_->set_products(model::select_products(config.precision, config.fp32_products, device));
  identity_ = checkpoint_identity(checkpoint_);
}

Session::Session(const Config& config, const torch::Device& device, model::TransHuman model,
                 std::shared_ptr<const data::Dataset> dataset, const torch::Tensor& canonical,
                 std::string identity)
    : config_(config),
      device_(device),
      checkpoint_(identity),  // what messages name
      identity_(std::move(identity)),
      dataset_(std::move(dataset)),
      canonical_(canonical),
      model_(std::move(model)) {
  tokens_ = std::make_unique<pipeline::Tokens>(*model_, canonical_);
}

std::string checkpoint_identity(const fs::path& checkpoint) {
  std::error_code ec;
  const auto bytes = fs::file_size(checkpoint, ec);
  const auto modified = fs::last_write_time(checkpoint, ec).time_since_epoch().count();
  return fs::absolute(checkpoint).lexically_normal().string() + " (" + std::to_string(bytes) +
         " bytes, modified " + std::to_string(modified) + ")";
}

std::string Session::checkpoint_id() const { return identity_; }

int Session::find_human(const std::string& name) const {
  const auto& humans = dataset_->humans();
  if (humans.empty()) fail("setting '", config_.eval.setting, "' has no people");
  if (name.empty()) return 0;
  std::string known;
  for (size_t i = 0; i < humans.size(); ++i) {
    if (humans[i]->name() == name) return int(i);
    known += (i ? ", " : "") + humans[i]->name();
  }
  fail("no person '", name, "' in setting '", config_.eval.setting, "' (it has: ", known, ")");
}

const data::HumanSequence& Session::human(int index) const {
  return *dataset_->humans().at(size_t(index));
}

std::vector<int> Session::setting_frames(int index) const { return dataset_->frames(index); }

torch::Tensor Session::body_center(int human_index, int frame) const {
  const auto& h = human(human_index);
  if (frame < 0 || frame >= h.num_frames())
    fail(h.name(), ": frame ", frame, " out of range [0, ", h.num_frames(), ")");
  const auto b = dataset_->load_body(h, frame).bounds.to(torch::kFloat64);
  return 0.5 * (b[0] + b[1]);
}

PreparedFrame Session::prepare(int human, int frame, int view) const {
  torch::NoGradGuard no_grad;
  PreparedFrame out;
  out.human = human;
  out.frame = frame;
  out.sample = dataset_->load_item({human, frame, view}, 0);
  out.inputs =
      pipeline::frame_inputs(out.sample, canonical_, tokens_->labels(out.sample.body), device_);
  out.cache = pipeline::prepare_frame(*model_, out.inputs, config_.render);
  return out;
}

PreparedFrame Session::prepare(data::Sample sample) const {
  torch::NoGradGuard no_grad;
  PreparedFrame out;
  out.human = find_human(sample.human);
  out.frame = sample.frame;
  out.sample = std::move(sample);
  out.inputs =
      pipeline::frame_inputs(out.sample, canonical_, tokens_->labels(out.sample.body), device_);
  out.cache = pipeline::prepare_frame(*model_, out.inputs, config_.render);
  return out;
}

pipeline::ViewResult Session::evaluate_view(int human_index, int frame, int view) const {
  const auto& h = human(human_index);
  if (frame < 0 || frame >= h.num_frames())
    fail(h.name(), ": frame ", frame, " out of range [0, ", h.num_frames(), ")");
  if (view < 0 || view >= h.num_cameras())
    fail(h.name(), ": camera ", view, " out of range [0, ", h.num_cameras(), ")");
  torch::NoGradGuard no_grad;
  const auto sample = dataset_->load_item({human_index, frame, view}, 0);
  const auto inputs =
      pipeline::frame_inputs(sample, canonical_, tokens_->labels(sample.body), device_);
  try {
    return pipeline::evaluate_view(*model_, config_.render, sample, inputs, nullptr, device_,
                                   nullptr);
  } catch (const Error& e) {
    fail("checkpoint '", checkpoint_.string(), "', ", e.what());
  }
}

video::PathCamera Session::dataset_camera(const PreparedFrame& frame, int view) const {
  const auto& h = human(frame.human);
  if (view < 0 || view >= h.num_cameras())
    fail(h.name(), ": camera ", view, " out of range [0, ", h.num_cameras(), ")");
  const auto& cam = h.camera(view);  // float64, scaled as the reader scales it
  auto K = cam.K.to(torch::kFloat64).clone();
  K.slice(0, 0, 2) *= config_.data.ratio;
  return {K, cam.R.to(torch::kFloat64), cam.T.to(torch::kFloat64).reshape({3, 1})};
}

torch::Tensor Session::render(const PreparedFrame& frame, const video::PathCamera& camera,
                              int width, int height, int64_t band_pixels) const {
  ViewControl control;
  control.band_pixels = band_pixels;
  return render_view(frame, camera, width, height, control)->rgb;
}

std::optional<Session::ViewImages> Session::render_view(const PreparedFrame& frame,
                                                        const video::PathCamera& camera, int width,
                                                        int height,
                                                        const ViewControl& control) const {
  torch::NoGradGuard no_grad;
  const int64_t n = int64_t(height) * width;
  auto rgb = torch::zeros({n, 3}, torch::kFloat32), depth = torch::zeros({n}, torch::kFloat32),
       acc = torch::zeros({n}, torch::kFloat32);
  const auto bounds = frame.sample.body.bounds.to(torch::kFloat64);
  RenderConfig config = config_.render;
  if (control.samples > 0) config.samples = control.samples;
  // A band of rows at a time: the rays' memory is bounded by the band, not by the image (a
  // 512x512 view is one band).
  const int64_t rows = std::max<int64_t>(1, control.band_pixels / width);
  bool cancelled = false;
  render::for_each_chunk(height, rows, [&](int64_t y0, int64_t y1) {
    if (cancelled || (control.cancelled && control.cancelled())) {
      cancelled = true;
      return;
    }
    auto pixels = data::pixel_grid(width, int(y1 - y0));
    pixels.select(1, 1).add_(y0);
    const auto rays = data::pixel_rays(pixels, camera.K, camera.R, camera.T);
    const auto nf = data::near_far(rays.origins, rays.dirs, bounds);
    const auto valid = nf.valid;
    auto f = [&](const torch::Tensor& t) { return t.index({valid}).to(device_, torch::kFloat32); };
    const render::Rays r{f(rays.origins), f(rays.dirs), f(nf.near), f(nf.far)};
    if (r.size() == 0) return;
    const auto vp = pixels.index({valid});
    const auto flat = vp.select(1, 1) * width + vp.select(1, 0);
    const auto result = pipeline::render(*model_, frame.cache, r, config, pipeline::kInference);
    rgb.index_copy_(0, flat, result.rgb.to(torch::kCPU, torch::kFloat32));
    depth.index_copy_(0, flat, result.depth.to(torch::kCPU, torch::kFloat32));
    acc.index_copy_(0, flat, result.acc.to(torch::kCPU, torch::kFloat32));
  });
  if (cancelled) return std::nullopt;
  pipeline::require_finite_output(rgb, "checkpoint '" + checkpoint_.string() + "', " +
                                           frame.sample.human + " frame " +
                                           std::to_string(frame.sample.frame));
  return ViewImages{rgb.view({height, width, 3}), depth.view({height, width}),
                    acc.view({height, width})};
}

resources::Estimate Session::render_estimate(const PreparedFrame& frame, int width, int height,
                                             int frames) const {
  const double pixels = double(width) * height;
  const double cache = frame.cache.nbytes();
  resources::Estimate e;
  e.what = fmt::format("render {} x {}{}", width, height,
                       frames > 1 ? fmt::format(" x {} frames", frames) : "");
  // The image (float RGB, its 8-bit copies for the PNG), one band of rays (float64 origins and
  // directions, near/far, pixel indices and their float32 copies), one chunk of the network.
  e.bytes = pixels * (12 + 6) + std::min(pixels, double(kRenderBandPixels)) * 200 + cache +
            double(config_.render.chunk_points) * resources::kBytesPerChunkPoint;
  e.samples = pixels * config_.render.samples * frames;
  e.threads = device_.is_cpu() ? torch::get_num_threads() : 0;
  return e;
}

torch::Tensor Session::density(const PreparedFrame& frame, const torch::Tensor& pts) const {
  TORCH_CHECK(pts.dim() == 2 && pts.size(1) == 3, "density: pts must be (N, 3), got ", pts.sizes());
  torch::NoGradGuard no_grad;
  auto out = torch::zeros({pts.size(0)}, torch::kFloat32);
  render::for_each_chunk(pts.size(0), config_.render.chunk_points, [&](int64_t b, int64_t e) {
    const auto p = pts.slice(0, b, e).to(device_, torch::kFloat32);
    const auto& body = frame.cache.geometry.body;  // null without a culling distance
    const auto kept = body ? body->near(p).nonzero().flatten()
                           : torch::arange(p.size(0), p.options().dtype(torch::kLong));
    if (kept.size(0) == 0) return;
    const auto sigma = model_->density(frame.cache, p.index_select(0, kept));
    out.slice(0, b, e).index_put_({kept.cpu()}, sigma.to(torch::kCPU, torch::kFloat32));
  });
  return out;
}

torch::Tensor Session::color(const PreparedFrame& frame, const torch::Tensor& pts,
                             const torch::Tensor& dirs) const {
  TORCH_CHECK(pts.dim() == 2 && pts.size(1) == 3 && dirs.sizes() == pts.sizes(),
              "color: pts and dirs must be (N, 3), got ", pts.sizes(), " and ", dirs.sizes());
  torch::NoGradGuard no_grad;
  return render::cat_chunks(pts.size(0), config_.render.chunk_points, [&](int64_t b, int64_t e) {
    const auto raw = model_->forward(frame.cache, pts.slice(0, b, e).to(device_, torch::kFloat32),
                                     dirs.slice(0, b, e).to(device_, torch::kFloat32));
    return torch::sigmoid(raw.slice(1, 0, 3)).to(torch::kCPU, torch::kFloat32);
  });
}

Session::DirectionalColors Session::colors_along(const PreparedFrame& frame,
                                                 const torch::Tensor& pts,
                                                 const torch::Tensor& directions) const {
  TORCH_CHECK(pts.dim() == 2 && pts.size(1) == 3, "colors_along: pts must be (N, 3), got ",
              pts.sizes());
  TORCH_CHECK(
      directions.size(-1) == 3 &&
          (directions.dim() == 2 || (directions.dim() == 3 && directions.size(1) == pts.size(0))),
      "colors_along: directions must be (K, 3) or (K, ", pts.size(0), ", 3), got ",
      directions.sizes());
  torch::NoGradGuard no_grad;
  const int64_t n = pts.size(0), k = directions.size(0);
  DirectionalColors out{torch::zeros({n}, torch::kFloat32),
                        torch::zeros({k, n, 3}, torch::kFloat32)};
  const auto dirs = directions.to(device_, torch::kFloat32);
  render::for_each_chunk(n, config_.render.chunk_points, [&](int64_t b, int64_t e) {
    const auto raw = model_->forward_directions(
        frame.cache, pts.slice(0, b, e).to(device_, torch::kFloat32),
        dirs.dim() == 3 ? dirs.slice(1, b, e) : dirs.unsqueeze(1).expand({k, e - b, 3}));
    auto sigma = raw.sigma;
    if (const auto& body = frame.cache.geometry.body)  // culled as density() culls
      sigma = torch::where(body->near(pts.slice(0, b, e).to(device_, torch::kFloat32)), sigma,
                           torch::zeros_like(sigma));
    out.sigma.slice(0, b, e).copy_(sigma.to(torch::kCPU, torch::kFloat32));
    out.rgb.slice(1, b, e).copy_(torch::sigmoid(raw.rgb).to(torch::kCPU, torch::kFloat32));
  });
  return out;
}

}  // namespace th::inference
