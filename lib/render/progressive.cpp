#include "render/progressive.hpp"

#include <torch/torch.h>

#include <algorithm>
#include <cmath>

#include "render/chunks.hpp"
#include "render/segments.hpp"

namespace th::render {
namespace {

// Samples per ray per round of the front-to-back march: small enough that a ray stops soon
// after its surface, large enough that a round fills the field's chunks.
int64_t march_step(int64_t samples) { return std::max<int64_t>(2, samples / 16); }

// The march keeps (rays x samples) masks and raw values of a whole batch: this many samples
// per batch (16 MiB of raw values) bound its memory.
constexpr int64_t kMarchSamples = int64_t(1) << 20;

}  // namespace

RenderResult render_progressive(RadianceField& field, const BodyDistance& body, const Rays& rays,
                                const RenderConfig& config, Profile* profile) {
  torch::NoGradGuard no_grad;
  const int64_t S = config.samples, R = rays.size(), chunk = config.chunk_points;
  const double tau = config.termination_transmittance;
  // Culling keeps a fraction of the samples: take several chunks' worth of rays per batch and
  // pass the kept samples to the field in full chunks. The march takes more rays per batch, so
  // that its later rounds (few samples per ray) still fill chunks.
  const int64_t batch =
      tau > 0 ? std::max<int64_t>(1, kMarchSamples / S) : std::max<int64_t>(1, 8 * chunk / S);
  RenderResult out;
  out.stats.rays = R;
  out.stats.points = R * S;
  out.rgb = torch::zeros({R, 3}, rays.origins.options());
  out.depth = torch::zeros({R}, rays.origins.options());
  out.acc = torch::zeros({R}, rays.origins.options());
  for_each_chunk(R, batch, [&](int64_t b, int64_t e) {
    const auto r = rays.slice(b, e);
    const int64_t n = r.size();
    torch::Tensor z, pts, keep;
    {
      ScopedTimer t(profile, "sampling");
      z = sample_depths(r.near, r.far, S, false);
      pts = (r.origins.unsqueeze(1) + r.directions.unsqueeze(1) * z.unsqueeze(2)).reshape({-1, 3});
    }
    {
      ScopedTimer t(profile, "culling");
      keep = body.near(pts).view({n, S});
    }
    const int64_t kept = keep.sum().item<int64_t>();
    out.stats.culled_points += n * S - kept;
    if (kept == 0) {
      out.stats.empty_rays += n;
      return;
    }
    auto raw = torch::zeros({n * S, 4}, pts.options());
    // Evaluates the samples `idx` (flat indices into the batch's n x S samples) in chunks.
    auto evaluate = [&](const torch::Tensor& idx) {
      for_each_chunk(idx.size(0), chunk, [&](int64_t c0, int64_t c1) {
        const auto part = idx.slice(0, c0, c1);
        const auto dirs = r.directions.index_select(0, torch::div(part, S, "floor"));
        const auto values = field.raw_density_first(pts.index_select(0, part), dirs);
        raw.index_copy_(0, part, values);
        out.stats.color_points += (values.select(1, 3) > 0).sum().item<int64_t>();
      });
      out.stats.density_points += idx.size(0);
    };
    const auto ray_kept = keep.sum(1);
    out.stats.empty_rays += n - (ray_kept > 0).sum().item<int64_t>();
    if (tau <= 0) {
      evaluate(keep.flatten().nonzero().flatten());
    } else {
      // Front to back: round k evaluates the kept samples of rank [k m, (k + 1) m) of every ray
      // still running; a ray stops when it has no kept samples left or its transmittance in
      // front of the next one, exp(sum log(1 - alpha + 1e-10)) as in compositing, is below tau.
      const int64_t m = march_step(S);
      const auto rank = keep.cumsum(1) - 1;  // the rank of each kept sample along its ray
      const auto lengths = segment_lengths(z, r.directions).flatten();
      auto log_trans = torch::zeros({n}, pts.options());
      auto running = ray_kept > 0;
      const double log_tau = std::log(tau);
      for (int64_t first = 0; running.any().item<bool>(); first += m) {
        torch::Tensor idx;
        {
          ScopedTimer t(profile, "culling");
          idx = (keep & rank.ge(first) & rank.lt(first + m) & running.unsqueeze(1))
                    .flatten()
                    .nonzero()
                    .flatten();
        }
        evaluate(idx);
        ScopedTimer t(profile, "compositing");
        const auto sigma = raw.index_select(0, idx).select(1, 3);
        const auto alpha = 1 - torch::exp(-torch::relu(sigma) * lengths.index_select(0, idx));
        log_trans.index_add_(0, torch::div(idx, S, "floor"), torch::log(1 - alpha + 1e-10));
        running = running & ray_kept.gt(first + m) & log_trans.ge(log_tau);
      }
    }
    ScopedTimer t(profile, "compositing");
    const auto comp = composite(raw.view({n, S, 4}), z, r.directions);
    out.rgb.slice(0, b, b + n).copy_(comp.rgb);
    out.depth.slice(0, b, b + n).copy_(comp.depth);
    out.acc.slice(0, b, b + n).copy_(comp.acc);
  });
  // Kept samples not evaluated: those the march skipped.
  out.stats.terminated_points =
      out.stats.points - out.stats.culled_points - out.stats.density_points;
  return out;
}

}  // namespace th::render
