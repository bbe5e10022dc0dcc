#pragma once
// METHOD 4: samples along rays, volume compositing, and the renderer that evaluates a radiance
// field in chunks (bounded memory for any number of rays).

#include <torch/types.h>

#include <chrono>
#include <cstdint>
#include <map>
#include <string>
#include <utility>
#include <vector>

#include "core/config.hpp"

namespace th::render {

class BodyDistance;

struct Rays {
  torch::Tensor origins;     // (R, 3) world
  torch::Tensor directions;  // (R, 3) world, not normalised (t is camera depth, METHOD 2.2)
  torch::Tensor near, far;   // (R)

  int64_t size() const { return origins.size(0); }
  Rays slice(int64_t begin, int64_t end) const;
  Rays index(const torch::Tensor& rows) const;
};

// The work of a stage as its operations count it (count_work): floating-point operations of the
// form that runs (a product of (M, K) by (K, N): 2 M K N; a transcendental function: one) and
// compulsory memory traffic (each operand read once, each result written once, a gathered table
// at most once).
struct Work {
  double flops = 0, bytes = 0;
};

// Wall time and work per named stage, accumulated (benchmarks; null pointer = off). Nested timers
// count exclusively: a stage's time excludes the stages timed inside it; work goes to the
// innermost open stage, "other" when none is open.
struct Profile {
  std::map<std::string, double> seconds;
  std::map<std::string, Work> work;
  std::vector<double> open;         // time of finished children, per open timer
  std::vector<const char*> stages;  // the open timers' stages, innermost last
};

namespace detail {
Profile*& thread_profile();  // the profile of the innermost timer open on this thread
}

// Adds work to the innermost stage open on this thread (nothing while no profile is on).
inline void count_work(double flops, double bytes) {
  Profile* p = detail::thread_profile();
  if (!p) return;
  auto& w = p->work[p->stages.empty() ? "other" : p->stages.back()];
  w.flops += flops;
  w.bytes += bytes;
}

class ScopedTimer {
 public:
  ScopedTimer(Profile* profile, const char* stage)
      : profile_(profile), stage_(stage), start_(std::chrono::steady_clock::now()) {
    if (!profile_) return;
    profile_->open.push_back(0.0);
    profile_->stages.push_back(stage);
    previous_ = std::exchange(detail::thread_profile(), profile_);
  }
  // A part of the stage open on this thread ("dparf.fields" inside "dparf"): timed under the
  // same profile, nothing when no profile is on.
  explicit ScopedTimer(const char* stage) : ScopedTimer(detail::thread_profile(), stage) {}
  ~ScopedTimer() {
    if (!profile_) return;
    const double elapsed =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count();
    const double children = profile_->open.back();
    profile_->open.pop_back();
    profile_->stages.pop_back();
    detail::thread_profile() = previous_;
    profile_->seconds[stage_] += elapsed - children;
    if (!profile_->open.empty()) profile_->open.back() += elapsed;
  }
  ScopedTimer(const ScopedTimer&) = delete;
  ScopedTimer& operator=(const ScopedTimer&) = delete;

 private:
  Profile* profile_;
  Profile* previous_ = nullptr;
  const char* stage_;
  std::chrono::steady_clock::time_point start_;
};

// What the renderer queries. raw = [rgb logits (3), density sigma_raw (1)].
class RadianceField {
 public:
  virtual ~RadianceField() = default;
  // pts, dirs: (N, 3) world sample positions and their rays' directions -> raw (N, 4).
  virtual torch::Tensor raw(const torch::Tensor& pts, const torch::Tensor& dirs) = 0;
  // As raw(), but the colour is evaluated only where sigma_raw > 0 (zero logits elsewhere):
  // such samples get zero weight, so the image is the same (METHOD 4, progressive rendering).
  virtual torch::Tensor raw_density_first(const torch::Tensor& pts, const torch::Tensor& dirs) {
    return raw(pts, dirs);
  }
};

// z = near (1 - t) + far t, t = linspace(0, 1, S); with `stratified`, uniform jitter inside the
// intervals between mid-points (training). near, far: (R) -> (R, S).
torch::Tensor sample_depths(const torch::Tensor& near, const torch::Tensor& far, int64_t samples,
                            bool stratified);

struct Composite {
  torch::Tensor rgb;      // (R, 3)
  torch::Tensor depth;    // (R)
  torch::Tensor acc;      // (R)
  torch::Tensor weights;  // (R, S)
};

// METHOD 4 compositing: delta_i = (z_{i+1} - z_i) |d| (last: 1e10 |d|), alpha = 1 -
// exp(-relu(sigma) delta), T_i = prod_{j<i} (1 - alpha_j + 1e-10), w = alpha T; rgb = sum w
// sigmoid(rgb_raw), depth = sum w z, acc = sum w; black background. raw: (R, S, 4), z: (R, S),
// directions: (R, 3).
Composite composite(const torch::Tensor& raw, const torch::Tensor& z,
                    const torch::Tensor& directions);

struct RenderStats {
  int64_t rays = 0;
  int64_t points = 0;             // rays x samples
  int64_t culled_points = 0;      // farther than the culling distance from the body
  int64_t density_points = 0;     // points whose density was evaluated
  int64_t color_points = 0;       // points whose colour was evaluated
  int64_t terminated_points = 0;  // kept points skipped by early ray termination
  int64_t empty_rays = 0;         // rays without any kept point (output 0)
};

struct RenderResult {
  torch::Tensor rgb, depth, acc;  // (R, 3), (R), (R)
  RenderStats stats;
};

// Renders every sample of every ray (training, and full rendering at inference). Without
// autograd the field is called on batches of at most config.chunk_points points; under autograd
// once for all rays (the field chunks internally, see model::FrameField). With `skip_far_from`
// (training with train.skip_far_points), samples farther than the culling distance from that
// body are skipped (raw = 0), as at inference.
class VolumeRenderer {
 public:
  explicit VolumeRenderer(const RenderConfig& config, Profile* profile = nullptr);

  RenderResult render(RadianceField& field, const Rays& rays, bool stratified,
                      const BodyDistance* skip_far_from = nullptr) const;

  const RenderConfig& config() const { return config_; }

 private:
  RenderConfig config_;
  Profile* profile_;
};

}  // namespace th::render
