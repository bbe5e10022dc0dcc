#include "data/dataset.hpp"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <chrono>
#include <mutex>
#include <numeric>
#include <random>
#include <set>

#include "body/smpl.hpp"
#include "body/visibility.hpp"
#include "core/error.hpp"
#include "data/calibration.hpp"
#include "data/h36m.hpp"
#include "data/rays.hpp"
#include "data/zju_mocap.hpp"
#include "geometry/camera.hpp"

namespace th::data {

namespace {

// Each distinct key's message once per process (the loader threads share it).
void warn_once(const std::string& message, const std::string& key = "") {
  static std::mutex mutex;
  static std::set<std::string> said;
  std::lock_guard<std::mutex> lock(mutex);
  if (said.insert(key.empty() ? message : key).second) spdlog::warn("{}", message);
}

// Calibration that cannot be right: an error, or (data.calibration_check: warn) one warning
// per `key` (a camera of a person).
void implausible(CalibrationCheck policy, const std::string& message, const std::string& key) {
  if (policy == CalibrationCheck::error)
    fail(message, " (data.calibration_check: warn to go on anyway)");
  warn_once(message + " (data.calibration_check: warn; going on)", key);
}

}  // namespace

namespace fs = std::filesystem;
using torch::indexing::Slice;

namespace {

torch::Tensor image_tensor(const cv::Mat& rgb) {  // CV_32FC3 -> (H, W, 3) float32
  return torch::from_blob(rgb.data, {rgb.rows, rgb.cols, 3}, torch::kFloat32).clone();
}

torch::Tensor mask_tensor(const cv::Mat& mask) {  // CV_8U -> (H, W) uint8
  return torch::from_blob(mask.data, {mask.rows, mask.cols}, torch::kUInt8).clone();
}

torch::Tensor f32(const torch::Tensor& t) { return t.to(torch::kFloat32).contiguous(); }

}  // namespace

std::shared_ptr<const body::SmplModel> load_body_model(const DataConfig& config) {
  const fs::path path = config.smpl_model.empty() ? fs::path(config.root) / "smpl_model.npz"
                                                  : fs::path(config.smpl_model);
  if (!fs::exists(path))
    fail("body model '", path.string(),
         "' does not exist (set data.smpl_model to SMPL's .pkl or "
         "an .npz; transhuman-synth writes <root>/smpl_model.npz)");
  return std::make_shared<const body::SmplModel>(body::load_smpl(path));
}

namespace {

SplitSetting setting_of(const DataConfig& config, const std::string& setting, Dataset::Mode mode) {
  if (config.split_file.empty())
    return whole_capture_setting(config.root, setting, mode == Dataset::Mode::Train,
                                 config.num_reference_views);
  return load_split(config.split_file, setting);
}

std::string camera_list(const HumanSequence& human, const std::vector<int>& cameras) {
  std::string out;
  for (int c : cameras) out += (out.empty() ? "" : ", ") + human.camera_name(c);
  return out;
}

}  // namespace

Dataset::Dataset(const DataConfig& config, const std::string& setting, Mode mode,
                 std::shared_ptr<const body::SmplModel> smpl)
    : config_(config),
      setting_(setting_of(config, setting, mode)),
      mode_(mode),
      smpl_(std::move(smpl)) {
  TORCH_CHECK(smpl_, "Dataset needs a body model");
  if (!fs::is_directory(config.root))
    fail("data.root '", config.root, "' does not exist",
         config.dataset == DatasetKind::synthetic
             ? " (make it with: transhuman-synth --out " + config.root + ")"
             : "");
  const std::string split = config.split_file.empty()
                                ? "data.root '" + config.root + "' (no split file)"
                                : "split '" + config.split_file + "', setting '" + setting + "'";
  for (const auto& range : setting_.humans) {
    auto human = open_human(human_folder(config.root, range.name, config.dataset),
                            {config.layout, config.person_id, smpl_, config.calibration_check});
    const int h = int(humans_.size());
    const std::string calibration = human->calibration_file().string();
    for (int c = 0; c < human->num_cameras(); ++c) {
      const auto& cam = human->camera(c);
      const std::string where = "'" + calibration + "': camera " + std::to_string(c) + ": ";
      const std::string named = " (camera '" + human->camera_name(c) + "')";
      const std::string unusable = unusable_intrinsics(cam.K);
      if (!unusable.empty()) fail(where, unusable, named);
      const std::string why = implausible_rotation(cam.R);
      if (!why.empty())
        implausible(config.calibration_check, where + why + named,
                    human->dir().string() + "#R" + std::to_string(c));
    }
    const std::vector<int> frames = range.frames(human->num_frames());
    if (frames.empty())
      fail(split, ": ", range.name, " has ", human->num_frames(),
           " frames, none of them from frame ", range.begin);
    // Reference views: data.reference_views, the setting's, or (no split) the most spread.
    Views views;
    const auto resolve = [&](const std::vector<CameraRef>& values, const std::string& where) {
      std::vector<int> out;
      for (const auto& v : values) out.push_back(camera_index(*human, v.text, where, v.index));
      return out;
    };
    // Reference cameras, each chosen once: an entry is a camera's name or an index.
    const auto references = [&](const std::vector<CameraRef>& values, const std::string& where) {
      const std::vector<int> out = resolve(values, where);
      const auto how = [&](size_t i) {
        const bool named = !values[i].index && human->camera_name(out[i]) == values[i].text;
        return "entry " + std::to_string(i) + " '" + values[i].text + "' is " +
               (named ? "its name" : "index " + std::to_string(out[i]));
      };
      for (size_t i = 0; i < out.size(); ++i)
        for (size_t j = 0; j < i; ++j)
          if (out[i] == out[j])
            fail(where, ": ", range.name, "'s camera '", human->camera_name(out[i]),
                 "' is chosen twice as a reference view (", how(j), ", ", how(i),
                 "): choose each camera once");
      return out;
    };
    // How many references the setting draws or spreads: from the split, or without one the key.
    const bool counted = setting_.random_references ||
                         (config.reference_views.empty() && setting_.reference_views.empty());
    if (counted && setting_.num_reference_views > human->num_cameras())
      fail(config.split_file.empty()
               ? "config key 'data.num_reference_views' = " +
                     std::to_string(setting_.num_reference_views) + " (" + split + ", setting '" +
                     setting + "')"
               : split + ": num_reference_views " + std::to_string(setting_.num_reference_views),
           ": ", range.name, " has only ", human->num_cameras(), " cameras");
    if (setting_.random_references && !config.reference_views.empty()) {
      const std::string message = "data.reference_views (--reference-views) fixes the reference " +
                                  std::string("cameras, but ") + split + " draws " +
                                  std::to_string(setting_.num_reference_views) +
                                  " at random per sample";
      // Training shares its config with evaluation, whose settings have fixed references.
      if (mode != Mode::Train) fail(message, ": use a setting with fixed references");
      warn_once(message + ": data.reference_views applies to evaluation only");
    }
    if (setting_.random_references) {
      // Drawn per sample (Dataset::load_item).
    } else if (!config.reference_views.empty()) {
      std::vector<CameraRef> values;
      for (const auto& v : config.reference_views) values.push_back({v, false});
      views.references = references(values, "data.reference_views");
      spdlog::info("{}: reference cameras {} (data.reference_views)", range.name,
                   camera_list(*human, views.references));
    } else if (!setting_.reference_views.empty()) {
      views.references = references(setting_.reference_views, split + ", reference_views");
    } else {
      views.references = spread_cameras(*human, human->load_vertices(frames.front()),
                                        setting_.num_reference_views);
      spdlog::info(
          "{}: reference cameras {}: the {} most evenly spread around the body "
          "(data.reference_views "
          "or --reference-views chooses others)",
          range.name, camera_list(*human, views.references), views.references.size());
    }
    if (setting_.all_targets) {
      for (int c = 0; c < human->num_cameras(); ++c)
        if (!setting_.targets_exclude_references ||
            std::find(views.references.begin(), views.references.end(), c) ==
                views.references.end())
          views.targets.push_back(c);
      // Rendering new views needs no target; evaluation does (require_targets).
      if (views.targets.empty() && no_targets_.empty())
        no_targets_ = split + ": " + range.name + " has no camera left as a target besides its " +
                      std::to_string(views.references.size()) + " reference views";
    } else {
      views.targets = resolve(setting_.target_views, split + ", target_views");
    }
    for (int frame : frames)
      for (int t : views.targets) items_.push_back({h, frame, t});
    views.frames = frames;
    humans_.push_back(std::move(human));
    views_.push_back(std::move(views));
  }
  spdlog::info("dataset: {} '{}' — {} humans, {} samples", config::name_of(config.dataset), setting,
               humans_.size(), items_.size());
}

void Dataset::require_targets() const {
  if (!no_targets_.empty()) fail(no_targets_);
}

const std::vector<int>& Dataset::frames(int human) const {
  reference_views(human);  // checks the index
  return views_[size_t(human)].frames;
}

const std::vector<int>& Dataset::reference_views(int human) const {
  return views_.at(size_t(human)).references;
}

FrameBody Dataset::load_body(const HumanSequence& human, int frame) const {
  const BodyParams params = human.load_params(frame);
  const torch::Tensor vertices = human.load_vertices(frame);
  if (vertices.size(0) != smpl_->num_vertices())
    fail(human.name(), " frame ", frame, ": the vertices file has ", vertices.size(0),
         " vertices but the body model has ", smpl_->num_vertices(),
         " (is data.smpl_model the model these fits were made with?)");
  const auto lbs = body::lbs(*smpl_, params.poses, params.shapes);
  FrameBody b;
  b.Rh = geometry::rodrigues(params.Rh);
  b.Th = params.Th;
  b.vertices = vertices;
  b.smpl_vertices = (vertices - params.Th.reshape({1, 3})).matmul(b.Rh);  // Rh^T (x - Th)
  b.A = lbs.A.index({Slice(), Slice(0, 3), Slice(0, 3)});
  b.bounds = bounds_of(vertices, config_.box_padding);
  for (auto* t : {&b.vertices, &b.smpl_vertices, &b.Rh, &b.Th, &b.A, &b.bounds}) *t = f32(*t);
  return b;
}

Sample Dataset::load(size_t index, uint64_t seed) const { return load_item(item(index), seed); }

Sample Dataset::load_item(const Item& it, uint64_t seed) const {
  if (it.human < 0 || size_t(it.human) >= humans_.size())
    fail("dataset '", setting_.name, "': no human #", it.human, " (it has ", humans_.size(), ")");
  const HumanSequence& human = *humans_[size_t(it.human)];
  if (it.frame < 0 || it.frame >= human.num_frames())
    fail(human.name(), ": no frame ", it.frame, " (it has ", human.num_frames(), ")");
  if (it.target_view < 0 || it.target_view >= human.num_cameras())
    fail(human.name(), ": no camera ", it.target_view, " (it has ", human.num_cameras(), ")");
  std::mt19937_64 rng(seed);
  const bool train = mode_ == Mode::Train;

  Sample s;
  s.human = human.name();
  s.frame = it.frame;
  s.target_view = it.target_view;
  if (setting_.random_references) {  // any cameras, the target included (METHOD 1.2)
    std::vector<int> all(human.num_cameras());
    std::iota(all.begin(), all.end(), 0);
    std::shuffle(all.begin(), all.end(), rng);
    s.reference_views.assign(all.begin(), all.begin() + setting_.num_reference_views);
  } else {
    s.reference_views = views_[size_t(it.human)].references;
  }
  JitterParams jitter;
  const bool jittered = train && config_.jitter.enabled;
  if (jittered) jitter = sample_jitter(config_.jitter, rng);

  // Reference views.
  std::vector<torch::Tensor> images, Ks, Rs, Ts, vis;
  s.body = load_body(human, it.frame);
  const auto faces = smpl_->faces;
  for (int v : s.reference_views) {
    const ViewImage view =
        load_view(human, it.frame, v, {config_.ratio, false, jittered ? &jitter : nullptr});
    const std::string why = implausible_view(s.body.vertices, view.camera.K, view.camera.R,
                                             view.camera.T, view.rgb.cols, view.rgb.rows);
    if (!why.empty())
      implausible(config_.calibration_check,
                  "'" + human.calibration_file().string() + "': reference camera " +
                      std::to_string(v) + " of frame " + std::to_string(it.frame) + ": " + why,
                  human.dir().string() + "#view" + std::to_string(v));
    const auto image_of = [&](int camera) {
      return "'" + human.image_path(it.frame, camera).string() + "' (camera '" +
             human.camera_name(camera) + "')";
    };
    if (cv::countNonZero(view.mask) == 0) {
      std::string files;
      for (const auto& f : human.mask_files(it.frame, v))
        files += (files.empty() ? "'" : ", '") + f.string() + "'";
      fail("reference view ", image_of(v), ": its mask ", files,
           " marks no person pixel (non-zero pixels mark the person)");
    }
    if (!images.empty() &&
        (images.front().size(1) != view.rgb.rows || images.front().size(2) != view.rgb.cols))
      fail("reference view ", image_of(v), " is ", view.rgb.cols, "x", view.rgb.rows,
           " at data.ratio ", config_.ratio, " but reference view ",
           image_of(s.reference_views.front()), " is ", images.front().size(2), "x",
           images.front().size(1), ": the reference views of a sample share one image size ",
           "(data.reference_views chooses others)");
    images.push_back(image_tensor(view.rgb).permute({2, 0, 1}));
    Ks.push_back(view.camera.K);
    Rs.push_back(view.camera.R);
    Ts.push_back(view.camera.T);
    if (config_.visibility == VisibilitySource::files) {
      const fs::path file = visibility_file(config_.visibility_root, human, it.frame, v);
      if (!fs::exists(file) && config_.visibility_missing == MissingVisibility::all_visible) {
        warn_once("visibility file '" + file.string() +
                  "' is missing: every vertex counts as visible " +
                  "(data.visibility_missing: all_visible, as the reference silently did)");
        vis.push_back(torch::ones({smpl_->num_vertices()}, torch::kBool));
      } else {
        if (!fs::exists(file))
          fail("visibility file '", file.string(), "' is missing (data.visibility: files; set ",
               "data.visibility_missing: all_visible to treat every vertex as visible instead)");
        vis.push_back(body::load_visibility_file(file, smpl_->num_vertices()));
      }
    } else {
      vis.push_back(body::vertex_visibility(s.body.vertices, faces, view.camera.K, view.camera.R,
                                            view.camera.T, view.rgb.cols, view.rgb.rows));
    }
  }
  s.ref_images = torch::stack(images).contiguous();
  s.ref_K = f32(torch::stack(Ks));
  s.ref_R = f32(torch::stack(Rs));
  s.ref_T = f32(torch::stack(Ts));
  s.visibility = torch::stack(vis);

  // Target view.
  const ViewImage target = load_view(human, it.frame, it.target_view,
                                     {config_.ratio, true, jittered ? &jitter : nullptr,
                                      config_.border_band == BorderBand::distorted});
  const int W = target.rgb.cols, H = target.rgb.rows;
  s.target_image = image_tensor(target.rgb);
  s.target_mask = mask_tensor(target.mask);
  s.K = f32(target.camera.K);
  s.R = f32(target.camera.R);
  s.T = f32(target.camera.T);
  const auto& cam = target.camera;
  const auto box = s.body.bounds.to(torch::kFloat64);

  torch::Tensor pixels;  // (N, 2) x, y
  if (train) {
    const cv::Mat bmask = box_mask(box, cam.K, cam.R, cam.T, W, H);
    // Patch centres on the person: every non-zero mask pixel inside the box, band and blended
    // edge values included, as the reference's `msk * bound_mask > 0` [parity].
    const cv::Mat person = (target.mask != 0) & (bmask != 0);
    const auto& p = config_.patch;
    if (config_.patch.size > W || config_.patch.size > H)
      fail("config key 'data.patch.size' = ", config_.patch.size, ": larger than the ", W, "x", H,
           " target image of '", human.name(), "' view ", s.target_view, " (at data.ratio ",
           config_.ratio, ")");
    if (cv::countNonZero(bmask) == 0)
      fail("sample '", human.name(), "' frame ", it.frame, ", target view ", s.target_view,
           ": the body's box is outside the image, no training patch can be sampled (is the body "
           "in that view? "
           "check the calibration in '",
           human.calibration_file().string(), "')");
    const auto patches = sample_patches(person / 255, bmask, p.count, p.size, p.body_prob, rng);
    s.patch_rgb = torch::zeros({int64_t(patches.size()), 3, p.size, p.size}, torch::kFloat32);
    std::vector<torch::Tensor> px, slot;
    for (size_t i = 0; i < patches.size(); ++i) {
      const Patch& q = patches[i];
      s.patch_rgb[i].index_put_(
          {Slice(), Slice(0, q.height), Slice(0, q.width)},
          s.target_image.index({Slice(q.y0, q.y0 + q.height), Slice(q.x0, q.x0 + q.width)})
              .permute({2, 0, 1}));
      auto local = pixel_grid(q.width, q.height);
      px.push_back(local + torch::tensor({q.x0, q.y0}, torch::kInt64));
      slot.push_back(int64_t(i) * p.size * p.size + local.select(1, 1) * p.size +
                     local.select(1, 0));
    }
    pixels = torch::cat(px);
    s.ray_patch_index = torch::cat(slot);
  } else {
    pixels = pixel_grid(W, H);
  }
  const auto rays = pixel_rays(pixels, cam.K, cam.R, cam.T);
  const auto nf = near_far(rays.origins, rays.dirs, box);
  const auto valid = nf.valid;
  if (!train) s.box_mask = valid.reshape({H, W});
  s.ray_o = f32(rays.origins.index({valid}));
  s.ray_d = f32(rays.dirs.index({valid}));
  s.near = f32(nf.near.index({valid}));
  s.far = f32(nf.far.index({valid}));
  const auto vp = pixels.index({valid});
  s.ray_pixel = vp.select(1, 1) * W + vp.select(1, 0);
  s.ray_rgb = s.target_image.reshape({-1, 3}).index({s.ray_pixel});
  if (train) s.ray_patch_index = s.ray_patch_index.index({valid});
  return s;
}

// ---- Prefetcher ---------------------------------------------------------------------------

Prefetcher::Prefetcher(std::shared_ptr<const Dataset> dataset, std::vector<size_t> order,
                       std::vector<uint64_t> seeds, int workers, int depth)
    : dataset_(std::move(dataset)),
      order_(std::move(order)),
      seeds_(std::move(seeds)),
      depth_(std::max(1, depth)) {
  TORCH_CHECK(order_.size() == seeds_.size(), "Prefetcher: one seed per sample");
  for (int i = 0; i < workers; ++i) threads_.emplace_back([this] { work(); });
}

Prefetcher::~Prefetcher() {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    stop_ = true;
  }
  cv_.notify_all();
  for (auto& t : threads_) t.join();
}

void Prefetcher::work() {
  for (;;) {
    size_t pos;
    {
      std::unique_lock<std::mutex> lock(mutex_);
      cv_.wait(lock,
               [&] { return stop_ || (claimed_ < order_.size() && claimed_ < next_ + depth_); });
      if (stop_ || claimed_ >= order_.size()) return;
      pos = claimed_++;
    }
    Sample sample;
    std::exception_ptr error;
    try {
      sample = dataset_->load(order_[pos], seeds_[pos]);
    } catch (...) {
      error = std::current_exception();
    }
    {
      std::lock_guard<std::mutex> lock(mutex_);
      if (error)
        errors_[pos] = error;
      else
        ready_.emplace(pos, std::move(sample));
    }
    cv_.notify_all();
  }
}

Sample Prefetcher::next() {
  TORCH_CHECK(!done(), "Prefetcher: no samples left");
  const size_t pos = next_;
  if (threads_.empty()) {
    ++next_;
    return dataset_->load(order_[pos], seeds_[pos]);
  }
  const auto t0 = std::chrono::steady_clock::now();
  std::unique_lock<std::mutex> lock(mutex_);
  cv_.wait(lock, [&] { return ready_.count(pos) || errors_.count(pos); });
  wait_seconds_ += std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  ++next_;
  cv_.notify_all();
  if (auto e = errors_.find(pos); e != errors_.end()) {
    auto error = e->second;
    errors_.erase(e);
    std::rethrow_exception(error);
  }
  Sample s = std::move(ready_.at(pos));
  ready_.erase(pos);
  return s;
}

}  // namespace th::data
