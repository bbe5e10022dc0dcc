// The rendering shortcuts against the exact render, on the tiny network trained
// until it has surfaces (CTest fixture `trained_tiny`, tests/configs/tiny_surface.yaml): a random
// field has no surface to stop at, so these checks need a trained one.
#include <torch/torch.h>

#include <catch2/catch.hpp>
#include <fstream>
#include <map>
#include <sstream>

#include "body/smpl.hpp"
#include "core/config_io.hpp"
#include "data/dataset.hpp"
#include "eval/evaluator.hpp"
#include "model/kernels/forms.hpp"
#include "model/transhuman.hpp"
#include "pipeline/checkpoint.hpp"
#include "pipeline/pipeline.hpp"
#include "render/progressive.hpp"
#include "support/test_env.hpp"
#include "trained_tiny.hpp"

namespace fs = std::filesystem;

using th::test::Frames;
using th::test::surface_config;
using th::test::trained_checkpoint;

namespace {

// The model's field, counting the samples it is asked to evaluate: the renderer's own counts
// are checked against it.
class CountingField : public th::render::RadianceField {
 public:
  CountingField(th::model::TransHumanImpl& model, const th::model::FrameCache& cache, int64_t chunk)
      : inner_(model, cache, chunk, false) {}
  torch::Tensor raw(const torch::Tensor& pts, const torch::Tensor& dirs) override {
    evaluated += pts.size(0);
    return inner_.raw(pts, dirs);
  }
  torch::Tensor raw_density_first(const torch::Tensor& pts, const torch::Tensor& dirs) override {
    evaluated += pts.size(0);
    return inner_.raw_density_first(pts, dirs);
  }
  int64_t evaluated = 0;

 private:
  th::model::FrameField inner_;
};

}  // namespace

TEST_CASE(
    "on a trained network, early ray termination stays within its bound of the exact render on "
    "every ray",
    "[inference][termination]") {
  torch::set_num_threads(1);
  Frames f(surface_config({"data.ratio=0.5"}));
  REQUIRE(f.config.render.termination_transmittance > 0);  // on by default
  REQUIRE(f.config.render.termination_transmittance <= 1e-3);
  // The default bound, and a loose one under which this briefly trained (still translucent)
  // network does stop rays: the bound (the transmittance left behind a stopped ray, plus float
  // rounding) holds either way; that rays really stop is checked under the loose one only, since
  // few rays of this network fall below the default's transmittance.
  for (double tau : {f.config.render.termination_transmittance, 0.1}) {
    for (int samples : {64, 16}) {
      auto exact_rc = f.config.render, fast_rc = f.config.render;
      exact_rc.samples = fast_rc.samples = samples;
      exact_rc.termination_transmittance = 0;
      fast_rc.termination_transmittance = tau;
      REQUIRE(fast_rc.progressive);
      const double tolerance = tau + 1e-6;
      int64_t kept = 0, terminated = 0;
      for (size_t i = 0; i < std::min<size_t>(f.dataset->size(), 4); ++i) {
        const auto s = f.dataset->load(i, 0);
        const auto inputs = f.inputs(s);
        torch::NoGradGuard no_grad;
        const auto cache = th::pipeline::prepare_frame(*f.model, inputs, f.config.render);
        const auto rays = th::pipeline::sample_rays(s, torch::kCPU);
        CountingField exact_field(*f.model, cache, exact_rc.chunk_points);
        CountingField fast_field(*f.model, cache, fast_rc.chunk_points);
        const auto& body = *cache.geometry.body;
        const auto exact = th::render::render_progressive(exact_field, body, rays, exact_rc);
        const auto fast = th::render::render_progressive(fast_field, body, rays, fast_rc);
        CAPTURE(tau, samples, s.human, s.frame, s.target_view);
        CHECK((fast.rgb - exact.rgb).abs().max().item<double>() <= tolerance);
        CHECK((fast.acc - exact.acc).abs().max().item<double>() <= tolerance);
        CHECK(exact.stats.density_points == exact_field.evaluated);
        CHECK(fast.stats.density_points == fast_field.evaluated);
        CHECK(fast.stats.terminated_points == exact_field.evaluated - fast_field.evaluated);
        CHECK(exact.acc.max().item<double>() > 0.5);  // the trained body is visible
        kept += exact.stats.density_points;
        terminated += fast.stats.terminated_points;
      }
      CAPTURE(tau, samples, kept, terminated);
      if (tau >= 0.1) CHECK(terminated * 20 > kept);  // at least 5% of the work skipped
    }
  }
}

TEST_CASE("on a trained network, readout windows render every ray as the per-level tables do",
          "[inference][windows]") {
  torch::set_num_threads(1);
  Frames f(surface_config({"data.ratio=0.5"}));
  for (int samples : {64, 16}) {
    auto rc = f.config.render;
    rc.samples = samples;
    for (size_t i = 0; i < std::min<size_t>(f.dataset->size(), 4); ++i) {
      const auto s = f.dataset->load(i, 0);
      torch::NoGradGuard no_grad;
      const auto a = th::pipeline::prepare_frame(*f.model, f.inputs(s), rc);
      // The level tables: the pixel stage a frame prepared in the LibTorch forms takes.
      const auto b = [&] {
        th::model::kernels::LibTorchForms libtorch_forms;
        return th::pipeline::prepare_frame(*f.model, f.inputs(s), rc);
      }();
      REQUIRE(std::holds_alternative<th::model::WindowReadouts>(a.pixels));
      REQUIRE(std::holds_alternative<th::model::PixelReadouts>(b.pixels));
      const auto rays = th::pipeline::sample_rays(s, torch::kCPU);
      const auto fast = th::pipeline::render(*f.model, a, rays, rc, th::pipeline::kInference);
      const auto exact = th::pipeline::render(*f.model, b, rays, rc, th::pipeline::kInference);
      CAPTURE(samples, s.human, s.frame, s.target_view);
      CHECK((fast.rgb - exact.rgb).abs().max().item<double>() <= 1e-3);
      CHECK((fast.acc - exact.acc).abs().max().item<double>() <= 1e-3);
      CHECK(fast.stats.density_points == exact.stats.density_points);
      CHECK(exact.acc.max().item<double>() > 0.5);
    }
  }
}

TEST_CASE(
    "a frame prepared once renders each of its views as preparing it for each does, bit for bit",
    "[inference][termination]") {
  torch::set_num_threads(1);
  Frames f(surface_config());
  th::pipeline::FrameReuse reuse;
  int compared = 0;
  for (size_t i = 0; i < std::min<size_t>(f.dataset->size(), 3); ++i) {
    const auto s = f.dataset->load(i, 0);
    const auto inputs = f.inputs(s);
    const auto alone =
        th::pipeline::evaluate_view(*f.model, f.config.render, s, inputs, nullptr, torch::kCPU);
    const auto shared = th::pipeline::evaluate_view(*f.model, f.config.render, s, inputs, nullptr,
                                                    torch::kCPU, &reuse);
    CAPTURE(s.human, s.frame, s.target_view);
    CHECK(torch::equal(alone.pred, shared.pred));
    CHECK(alone.psnr == shared.psnr);
    ++compared;
  }
  CHECK(compared == 3);
  CHECK(reuse.prepared() == 1);  // the first three test views are views of one frame
  CHECK(reuse.reused() == 2);
  // Other inputs (another frame's body) are prepared again.
  auto s = f.dataset->load(0, 0);
  auto inputs = f.inputs(s);
  inputs.Th = inputs.Th + 1e-3;
  reuse.prepare(*f.model, inputs, f.config.render);
  CHECK(reuse.prepared() == 2);
}

TEST_CASE(
    "evaluation with the default shortcuts scores every image as the exact settings do, to 0.01 dB",
    "[inference][termination]") {
  auto read_rows = [](const fs::path& csv) {
    std::ifstream in(csv);
    std::string line;
    std::getline(in, line);
    std::map<std::string, std::vector<double>> rows;  // human,frame,view -> psnr, ssim, evaluated
    while (std::getline(in, line)) {
      std::vector<std::string> c;
      std::stringstream cells(line);
      for (std::string cell; std::getline(cells, cell, ',');) c.push_back(cell);
      REQUIRE(c.size() == 11);
      rows[c[0] + "," + c[1] + "," + c[2]] = {std::stod(c[3]), std::stod(c[4]), std::stod(c[9])};
    }
    return rows;
  };
  const fs::path dir = th::test::scratch_dir("termination_eval");
  fs::create_directories(dir / "fast");
  fs::create_directories(dir / "exact");
  const std::vector<std::string> limit{"eval.limit=6", "render.samples=64", "threads=1"};
  auto exact_overrides = limit;
  exact_overrides.insert(exact_overrides.end(),
                         {"render.termination_transmittance=0", "eval.reuse_frames=false"});
  th::eval::evaluate(surface_config(limit), torch::kCPU, trained_checkpoint(), dir / "fast");
  th::eval::evaluate(surface_config(exact_overrides), torch::kCPU, trained_checkpoint(),
                     dir / "exact");
  const auto fast = read_rows(dir / "fast" / "per_image.csv"),
             exact = read_rows(dir / "exact" / "per_image.csv");
  REQUIRE(fast.size() == 6);
  REQUIRE(exact.size() == 6);
  double fast_points = 0, exact_points = 0;
  for (const auto& [key, e] : exact) {
    CAPTURE(key);
    REQUIRE(fast.count(key));
    const auto& q = fast.at(key);
    CHECK(std::abs(q[0] - e[0]) <= 0.01);  // PSNR, dB
    CHECK(std::abs(q[1] - e[1]) <= 1e-3);  // SSIM
    fast_points += q[2];
    exact_points += e[2];
  }
  CHECK(fast_points <= exact_points);  // fewer where rays stop (none may, on a translucent network)
}
