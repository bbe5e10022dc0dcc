#include "render/volume.hpp"

#include <torch/torch.h>

#include <algorithm>

#include "render/body_distance.hpp"
#include "render/chunks.hpp"
#include "render/segments.hpp"

namespace th::render {

Rays Rays::slice(int64_t begin, int64_t end) const {
  return {origins.slice(0, begin, end), directions.slice(0, begin, end), near.slice(0, begin, end),
          far.slice(0, begin, end)};
}

Rays Rays::index(const torch::Tensor& rows) const {
  return {origins.index_select(0, rows), directions.index_select(0, rows),
          near.index_select(0, rows), far.index_select(0, rows)};
}

torch::Tensor sample_depths(const torch::Tensor& near, const torch::Tensor& far, int64_t samples,
                            bool stratified) {
  TORCH_CHECK(near.dim() == 1 && far.sizes() == near.sizes(), "near/far must be (R), got ",
              near.sizes(), " and ", far.sizes());
  const auto t = torch::linspace(0, 1, samples, near.options());
  auto z = near.unsqueeze(1) * (1 - t) + far.unsqueeze(1) * t;
  if (stratified) {
    const auto mids = 0.5 * (z.narrow(1, 1, samples - 1) + z.narrow(1, 0, samples - 1));
    const auto upper = torch::cat({mids, z.narrow(1, samples - 1, 1)}, 1);
    const auto lower = torch::cat({z.narrow(1, 0, 1), mids}, 1);
    z = lower + (upper - lower) * torch::rand_like(z);
  }
  return z;
}

torch::Tensor segment_lengths(const torch::Tensor& z, const torch::Tensor& directions) {
  const auto S = z.size(1);
  return torch::cat({z.narrow(1, 1, S - 1) - z.narrow(1, 0, S - 1),
                     torch::full({z.size(0), 1}, 1e10, z.options())},
                    1) *
         directions.norm(2, 1, true);
}

Composite composite(const torch::Tensor& raw, const torch::Tensor& z,
                    const torch::Tensor& directions) {
  TORCH_CHECK(raw.dim() == 3 && raw.size(2) == 4, "raw must be (R, S, 4), got ", raw.sizes());
  TORCH_CHECK(z.sizes() == raw.sizes().slice(0, 2), "z must be (R, S) like raw, got ", z.sizes());
  TORCH_CHECK(directions.dim() == 2 && directions.size(0) == raw.size(0),
              "directions must be (R, 3)");
  const auto S = z.size(1);
  const auto dists = segment_lengths(z, directions);
  const auto rgb = torch::sigmoid(raw.narrow(2, 0, 3));
  const auto alpha = 1 - torch::exp(-torch::relu(raw.select(2, 3)) * dists);
  // Exclusive cumulative product of (1 - alpha + 1e-10).
  const auto trans =
      torch::cumprod(torch::cat({torch::ones({z.size(0), 1}, z.options()), 1 - alpha + 1e-10}, 1),
                     1)
          .narrow(1, 0, S);
  Composite c;
  c.weights = alpha * trans;
  c.rgb = (c.weights.unsqueeze(2) * rgb).sum(1);
  c.depth = (c.weights * z).sum(1);
  c.acc = c.weights.sum(1);
  return c;
}

Profile*& detail::thread_profile() {
  thread_local Profile* profile = nullptr;
  return profile;
}

VolumeRenderer::VolumeRenderer(const RenderConfig& config, Profile* profile)
    : config_(config), profile_(profile) {}

RenderResult VolumeRenderer::render(RadianceField& field, const Rays& rays, bool stratified,
                                    const BodyDistance* skip_far_from) const {
  const int64_t S = config_.samples, R = rays.size();
  // Without autograd, ray batches of chunk_points samples bound the memory. With autograd the
  // field bounds it (FrameField recomputes its chunks in the backward pass) and one call for all
  // rays lets it build its per-frame gradient buffers once.
  const int64_t batch = torch::GradMode::is_enabled()
                            ? std::max<int64_t>(R, 1)
                            : std::max<int64_t>(1, config_.chunk_points / S);
  std::vector<torch::Tensor> rgb, depth, acc;
  RenderResult out;
  out.stats.rays = R;
  out.stats.points = R * S;
  for_each_chunk(R, batch, [&](int64_t b, int64_t e) {
    const auto r = rays.slice(b, e);
    torch::Tensor z, pts, dirs;
    {
      ScopedTimer t(profile_, "sampling");
      z = sample_depths(r.near, r.far, S, stratified);
      pts = (r.origins.unsqueeze(1) + r.directions.unsqueeze(1) * z.unsqueeze(2)).reshape({-1, 3});
      dirs = r.directions.unsqueeze(1).expand({r.size(), S, 3}).reshape({-1, 3});
    }
    torch::Tensor raw;
    if (skip_far_from) {
      torch::Tensor keep;
      {
        ScopedTimer t(profile_, "culling");
        keep = skip_far_from->near(pts).nonzero().flatten();
      }
      out.stats.culled_points += pts.size(0) - keep.size(0);
      const auto kept = field.raw(pts.index_select(0, keep), dirs.index_select(0, keep));
      raw = torch::zeros({pts.size(0), 4}, kept.options()).index_copy(0, keep, kept);
      out.stats.density_points += keep.size(0);
      out.stats.color_points += keep.size(0);
    } else {
      raw = field.raw(pts, dirs);
      out.stats.density_points += pts.size(0);
      out.stats.color_points += pts.size(0);
    }
    ScopedTimer t(profile_, "compositing");
    const auto c = composite(raw.view({r.size(), S, 4}), z, r.directions);
    rgb.push_back(c.rgb);
    depth.push_back(c.depth);
    acc.push_back(c.acc);
  });
  if (R == 0) {
    out.rgb = torch::zeros({0, 3}, rays.origins.options());
    out.depth = out.acc = torch::zeros({0}, rays.origins.options());
    return out;
  }
  out.rgb = torch::cat(rgb);
  out.depth = torch::cat(depth);
  out.acc = torch::cat(acc);
  return out;
}

}  // namespace th::render
