#include "render/progressive.hpp"

#include <torch/torch.h>

#include <algorithm>

namespace th::render {

RenderResult render_progressive(RadianceField& field, const BodyDistance& body, const Rays& rays,
                                const RenderConfig& config, Profile* profile) {
  torch::NoGradGuard no_grad;
  const int64_t S = config.samples, R = rays.size(), chunk = config.chunk_points;
  // Culling keeps a fraction of the samples: take several chunks' worth of rays per batch and
  // pass the kept samples to the field in full chunks.
  const int64_t batch = std::max<int64_t>(1, 8 * chunk / S);
  RenderResult out;
  out.stats.rays = R;
  out.stats.points = R * S;
  out.rgb = torch::zeros({R, 3}, rays.origins.options());
  out.depth = torch::zeros({R}, rays.origins.options());
  out.acc = torch::zeros({R}, rays.origins.options());
  for (int64_t b = 0; b < R; b += batch) {
    const auto r = rays.slice(b, std::min(R, b + batch));
    const int64_t n = r.size();
    torch::Tensor z, pts, keep;
    {
      ScopedTimer t(profile, "sampling");
      z = sample_depths(r.near, r.far, S, false);
      pts = (r.origins.unsqueeze(1) + r.directions.unsqueeze(1) * z.unsqueeze(2)).reshape({-1, 3});
    }
    {
      ScopedTimer t(profile, "culling");
      keep = body.near(pts).nonzero().flatten();
    }
    out.stats.culled_points += pts.size(0) - keep.size(0);
    out.stats.density_points += keep.size(0);
    if (keep.size(0) == 0) {
      out.stats.empty_rays += n;
      continue;
    }
    auto raw = torch::zeros({n * S, 4}, pts.options());
    for (int64_t c = 0; c < keep.size(0); c += chunk) {
      const auto idx = keep.slice(0, c, std::min(keep.size(0), c + chunk));
      const auto dirs = r.directions.index_select(0, torch::div(idx, S, "floor"));
      const auto kept = field.raw_density_first(pts.index_select(0, idx), dirs);
      raw.index_copy_(0, idx, kept);
      out.stats.color_points += (kept.select(1, 3) > 0).sum().item<int64_t>();
    }
    const auto ray_has_point = torch::zeros({n}, torch::kBool).to(pts.device())
                                   .index_fill_(0, torch::div(keep, S, "floor"), true);
    out.stats.empty_rays += n - ray_has_point.sum().item<int64_t>();
    ScopedTimer t(profile, "compositing");
    const auto comp = composite(raw.view({n, S, 4}), z, r.directions);
    out.rgb.slice(0, b, b + n).copy_(comp.rgb);
    out.depth.slice(0, b, b + n).copy_(comp.depth);
    out.acc.slice(0, b, b + n).copy_(comp.acc);
  }
  return out;
}

}  // namespace th::render
