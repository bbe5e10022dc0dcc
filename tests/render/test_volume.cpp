// Sampling along rays, the body-distance structure, progressive vs full rendering.
#include <torch/torch.h>

#include <catch2/catch.hpp>

#include "model/frame_fixture.hpp"
#include "model/transhuman.hpp"
#include "render/body_distance.hpp"
#include "render/progressive.hpp"
#include "render/volume.hpp"

using namespace th;

namespace {

// A field whose density depends on the distance to the body and vanishes beyond 0.08 m, with a
// position-dependent colour; it counts the points it evaluates. `scale`: density per metre
// inside 0.08 m.
class DistanceField : public render::RadianceField {
 public:
  explicit DistanceField(torch::Tensor vertices, double scale = 200)
      : v_(std::move(vertices)), scale_(scale) {}
  torch::Tensor raw(const torch::Tensor& pts, const torch::Tensor& dirs) override {
    evaluated += pts.size(0);
    const auto d = std::get<0>(torch::cdist(pts, v_).min(1));
    const auto sigma = scale_ * (0.08 - d);  // negative beyond 0.08 m
    const auto rgb = torch::sin(5 * pts) + 0.1 * dirs;
    return torch::cat({rgb, sigma.unsqueeze(1)}, 1);
  }
  int64_t evaluated = 0;

 private:
  torch::Tensor v_;
  double scale_;
};

}  // namespace

TEST_CASE("sample depths: linspace at inference, one jittered sample per interval in training",
          "[render]") {
  const auto near = torch::tensor({1.0f, 2.0f}), far = torch::tensor({3.0f, 2.5f});
  const auto z = render::sample_depths(near, far, 5, false);
  CHECK(torch::allclose(z[0], torch::tensor({1.0f, 1.5f, 2.0f, 2.5f, 3.0f})));
  const auto zs = render::sample_depths(near, far, 5, true);
  const auto mids = 0.5 * (z.narrow(1, 1, 4) + z.narrow(1, 0, 4));
  const auto lower = torch::cat({z.narrow(1, 0, 1), mids}, 1),
             upper = torch::cat({mids, z.narrow(1, 4, 1)}, 1);
  CHECK(((zs >= lower) & (zs <= upper)).all().item<bool>());
}

TEST_CASE("the body-distance grid answers like all pairwise distances", "[render][culling]") {
  torch::manual_seed(0);
  const auto v = torch::randn({500, 3}) * torch::tensor({0.2, 0.6, 0.1});
  for (double r : {0.1, 0.03, 0.5}) {
    render::BodyDistance body(v, r);
    auto pts = torch::randn({20000, 3}) * torch::tensor({0.4, 0.9, 0.3});
    // points at distance ~r from a vertex, on both sides
    const auto dir = torch::randn({2000, 3});
    const auto near_r = v.narrow(0, 0, 2000 % 500 == 0 ? 500 : 500).repeat({4, 1}) +
                        dir / dir.norm(2, 1, true) * r * (1 + 1e-3 * torch::randn({2000, 1}));
    pts = torch::cat({pts, near_r});
    const auto fast = body.near(pts), brute = render::BodyDistance::near_brute_force(pts, v, r);
    CHECK(torch::equal(fast, brute));
    CHECK(fast.sum().item<int64_t>() > 0);
    CHECK(fast.logical_not().sum().item<int64_t>() > 0);
  }
}

TEST_CASE("progressive rendering equals full rendering and reports skipped points",
          "[render][progressive]") {
  const auto frame = test::synthetic_frame();
  const auto rays = test::target_rays(frame, 24);
  REQUIRE(rays.size() > 100);
  RenderConfig rc;
  rc.samples = 64;
  rc.chunk_points = 1024;
  rc.termination_transmittance = 0;  // every kept sample (early termination: the next test)
  const render::BodyDistance body(frame.inputs.vertices, rc.cull_distance);

  SECTION("a field with no density beyond the culling distance") {
    DistanceField field(frame.inputs.vertices);
    const auto full = render::VolumeRenderer(rc).render(field, rays, false);
    const int64_t full_points = field.evaluated;
    field.evaluated = 0;
    const auto prog = render::render_progressive(field, body, rays, rc);
    CHECK(full.acc.max().item<double>() > 0.5);  // the body is visible
    CHECK((full.rgb - prog.rgb).abs().max().item<double>() < 1e-5);
    CHECK((full.depth - prog.depth).abs().max().item<double>() < 1e-5);
    CHECK((full.acc - prog.acc).abs().max().item<double>() < 1e-5);
    CHECK(full_points == rays.size() * 64);
    CHECK(prog.stats.points == full_points);
    CHECK(prog.stats.culled_points > 0);
    CHECK(prog.stats.culled_points + prog.stats.density_points == prog.stats.points);
    CHECK(field.evaluated == prog.stats.density_points);
    CHECK(prog.stats.color_points < prog.stats.density_points);
    CHECK(prog.stats.empty_rays > 0);
  }

  SECTION("the TransHuman model: culled full rendering, density-first colour, chunking") {
    torch::manual_seed(3);
    model::TransHuman net(test::tiny_model_config());
    net->eval();
    test::center_density(*net, frame, 100.0);
    torch::NoGradGuard ng;
    const auto cache = net->prepare(frame.inputs, rc.cull_distance);
    model::FrameField field(*net, cache, rc.chunk_points);
    // Reference: every point evaluated densely, raw zeroed where all vertices are >= 0.1 m away
    // (brute-force distances), then composited.
    const auto z = render::sample_depths(rays.near, rays.far, 64, false);
    const auto pts = (rays.origins.unsqueeze(1) + rays.directions.unsqueeze(1) * z.unsqueeze(2))
                         .reshape({-1, 3});
    const auto dirs = rays.directions.unsqueeze(1).expand({rays.size(), 64, 3}).reshape({-1, 3});
    auto raw = field.raw(pts, dirs);
    const auto keep = render::BodyDistance::near_brute_force(pts, frame.inputs.vertices, 0.1);
    raw = raw * keep.unsqueeze(1).to(raw.dtype());
    const auto ref = render::composite(raw.view({rays.size(), 64, 4}), z, rays.directions);
    const auto prog = render::render_progressive(field, body, rays, rc);
    CHECK(ref.acc.max().item<double>() > 0.1);
    CHECK((ref.rgb - prog.rgb).abs().max().item<double>() < 1e-5);
    CHECK((ref.depth - prog.depth).abs().max().item<double>() < 1e-5);
    CHECK((ref.acc - prog.acc).abs().max().item<double>() < 1e-5);
    CHECK(prog.stats.culled_points == (~keep).sum().item<int64_t>());
    CHECK(prog.stats.color_points < prog.stats.density_points);
    // The full renderer with culling (training's skip_far_points) and another chunk size.
    auto rc2 = rc;
    rc2.chunk_points = 4096;
    model::FrameField field2(*net, cache, rc2.chunk_points);
    const auto culled_full = render::VolumeRenderer(rc2).render(field2, rays, false, &body);
    CHECK((culled_full.rgb - prog.rgb).abs().max().item<double>() < 1e-5);
  }
}

TEST_CASE("early ray termination moves no ray by more than its transmittance bound",
          "[render][progressive]") {
  const auto frame = test::synthetic_frame();
  const auto rays = test::target_rays(frame, 24);
  RenderConfig rc;
  rc.chunk_points = 1024;
  const render::BodyDistance body(frame.inputs.vertices, rc.cull_distance);
  for (int samples : {64, 16}) {
    rc.samples = samples;
    DistanceField field(frame.inputs.vertices, 1e4);  // opaque within a few millimetres
    rc.termination_transmittance = 0;
    field.evaluated = 0;
    const auto exact = render::render_progressive(field, body, rays, rc);
    const int64_t exact_evaluated = field.evaluated;  // counted by the field, not by the renderer
    REQUIRE(exact.acc.max().item<double>() > 1 - 1e-4);
    CHECK(exact.stats.density_points == exact_evaluated);
    for (double tau : {1e-4, 1e-3, 1e-2}) {
      CAPTURE(samples, tau);
      rc.termination_transmittance = tau;
      field.evaluated = 0;
      const auto fast = render::render_progressive(field, body, rays, rc);
      CHECK((fast.rgb - exact.rgb).abs().max().item<double>() <= tau);
      CHECK((fast.acc - exact.acc).abs().max().item<double>() <= tau);
      CHECK(fast.stats.culled_points == exact.stats.culled_points);
      CHECK(fast.stats.empty_rays == exact.stats.empty_rays);
      CHECK(fast.stats.terminated_points > 0);  // the body is opaque: rays stop inside it
      CHECK(field.evaluated == fast.stats.density_points);
      CHECK(fast.stats.terminated_points == exact_evaluated - field.evaluated);
      CHECK(exact.stats.terminated_points == 0);
    }
  }

  SECTION("a field that never becomes opaque: nothing stops, the image is the exact one") {
    class Faint : public render::RadianceField {
     public:
      torch::Tensor raw(const torch::Tensor& pts, const torch::Tensor&) override {
        return torch::cat({pts, torch::full({pts.size(0), 1}, 1e-3, pts.options())}, 1);
      }
    } faint;
    rc.samples = 64;
    rc.termination_transmittance = 0;
    const auto exact = render::render_progressive(faint, body, rays, rc);
    rc.termination_transmittance = 1e-4;
    const auto fast = render::render_progressive(faint, body, rays, rc);
    CHECK(fast.stats.terminated_points == 0);
    CHECK(torch::equal(fast.rgb, exact.rgb));
    CHECK(torch::equal(fast.acc, exact.acc));
  }
}
