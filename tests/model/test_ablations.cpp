// Every ablation of the paper as configuration: builds, trains one step, renders one image.
#include <torch/torch.h>

#include <catch2/catch.hpp>

#include "core/error.hpp"
#include "model/frame_fixture.hpp"
#include "model/transhuman.hpp"
#include "pipeline/pipeline.hpp"
#include "render/progressive.hpp"

using namespace th;
using namespace th::model;

namespace {

// Voxel-grid labels (the grid groupings of METHOD 2.5): many voxel ids stay empty.
torch::Tensor grid_labels(const torch::Tensor& points, double cell) {
  const auto p = points.to(torch::kDouble);
  const auto c = ((p - std::get<0>(p.min(0))) / cell).floor().to(torch::kLong);
  const auto dims = std::get<0>(c.max(0)) + 1;
  return (c.select(1, 2) * dims[1] + c.select(1, 1)) * dims[0] + c.select(1, 0);
}

struct Ablation {
  std::string name;
  std::function<void(ModelConfig&, RenderConfig&)> configure = nullptr;
  std::function<void(model::FrameInputs&)> labels = nullptr;  // optional relabelling
  int64_t vertices = 300, tokens = 24;
  bool skip_far_points = false;
};

void train_step_and_render(const Ablation& ab) {
  auto cfg = test::tiny_model_config();
  RenderConfig rc;
  rc.chunk_points = 2048;
  rc.train_chunk_points = 1024;
  ab.configure(cfg, rc);
  cfg.grouping.num_tokens = static_cast<int>(ab.tokens);
  config::check(cfg, "model");
  config::check(rc, "render");
  auto frame = test::synthetic_frame(ab.vertices, ab.tokens);
  if (ab.labels) ab.labels(frame.inputs);
  torch::manual_seed(1);
  TransHuman model(cfg);
  model->train();
  test::center_density(*model, frame);
  torch::optim::Adam adam(model->parameters(), torch::optim::AdamOptions(7e-4));
  const auto before = model->parameters();
  std::vector<torch::Tensor> snapshot;
  for (const auto& p : before) snapshot.push_back(p.detach().clone());
  // One training step (stratified samples, MSE).
  {
    const auto cache = model->prepare(frame.inputs, rc.cull_distance);
    const auto rays = test::target_rays(frame, 10);
    const auto out = pipeline::render(*model, cache, rays, rc, {true, ab.skip_far_points});
    const auto loss = (out.rgb - 0.5).pow(2).mean();
    adam.zero_grad();
    loss.backward();
    adam.step();
    CHECK(std::isfinite(loss.item<double>()));
  }
  int changed = 0;
  for (size_t i = 0; i < before.size(); ++i) changed += !torch::equal(before[i], snapshot[i]);
  CHECK(changed > 0);
  // One image (progressive rendering).
  model->eval();
  torch::NoGradGuard ng;
  const auto cache = model->prepare(frame.inputs, rc.cull_distance);
  const auto rays = test::target_rays(frame, 16);
  const auto img = pipeline::render(*model, cache, rays, rc, pipeline::kInference);
  CHECK(img.rgb.size(0) == rays.size());
  CHECK(torch::isfinite(img.rgb).all().item<bool>());
  CHECK(img.stats.density_points > 0);
}

}  // namespace

TEST_CASE("every ablation builds, trains one step and renders one image", "[model][ablations]") {
  std::vector<Ablation> ablations = {
      {"default", [](ModelConfig&, RenderConfig&) {}},
      {"observation-space grouping and PE",
       [](ModelConfig& c, RenderConfig&) {
         c.grouping.kind = GroupingKind::observation_grid,
         c.transhe.position = TokenPosition::observation;
       },
       [](FrameInputs& in) {
         in.labels = grid_labels(in.vertices, 0.12);
         in.num_tokens = in.labels.max().item<int64_t>() + 1;
       }},
      {"observation PE only",
       [](ModelConfig& c, RenderConfig&) { c.transhe.position = TokenPosition::observation; }},
      {"canonical grid",
       [](ModelConfig& c, RenderConfig&) { c.grouping.kind = GroupingKind::canonical_grid; },
       [](FrameInputs& in) {
         in.labels = grid_labels(in.canonical, 0.12);
         in.num_tokens = in.labels.max().item<int64_t>() + 1;
       }},
      {"Nt 100", [](ModelConfig&, RenderConfig&) {}, nullptr, 1200, 100},
      {"Nt 300", [](ModelConfig&, RenderConfig&) {}, nullptr, 1200, 300},
      {"Nt 500", [](ModelConfig&, RenderConfig&) {}, nullptr, 1200, 500},
      {"Nt 1000", [](ModelConfig&, RenderConfig&) {}, nullptr, 1200, 1000},
      {"w/o transformer", [](ModelConfig& c, RenderConfig&) { c.transhe.enabled = false; }},
      {"coordinate none",
       [](ModelConfig& c, RenderConfig&) { c.dparf.coordinate = Coordinate::none; }},
      {"coordinate absolute",
       [](ModelConfig& c, RenderConfig&) { c.dparf.coordinate = Coordinate::absolute; }},
      {"FDI w/o a", [](ModelConfig& c, RenderConfig&) { c.fdi.appearance = false; }},
      {"FDI w/o h", [](ModelConfig& c, RenderConfig&) { c.fdi.human = false; }},
      {"FDI w/o RGB", [](ModelConfig& c, RenderConfig&) { c.fdi.raw_rgb = false; }},
      {"SPC + trilinear",
       [](ModelConfig& c, RenderConfig&) {
         c.representation = Representation::spc_trilinear, c.spc.voxel_size = 0.05,
         c.spc.channels = 16;
       }},
      {"16 samples", [](ModelConfig&, RenderConfig& r) { r.samples = 16; }},
      {"training skips far points, full (non-progressive) inference",
       [](ModelConfig&, RenderConfig& r) { r.progressive = false, r.train_chunk_points = 256; },
       nullptr, 300, 24, true},
      {"fused PE rounding, running BatchNorm statistics",
       [](ModelConfig& c, RenderConfig&) {
         c.transhe.pe_rounding = PeRounding::fused, c.encoder.batchnorm = BatchNormStats::running;
       }},
  };
  for (int nk = 1; nk <= 9; ++nk)
    ablations.push_back(
        {"Nk " + std::to_string(nk), [nk](ModelConfig& c, RenderConfig&) { c.dparf.nk = nk; }});
  for (const auto& ab : ablations) {
    DYNAMIC_SECTION(ab.name) { train_step_and_render(ab); }
  }
}

TEST_CASE("configurations combining incompatible switches are refused with a reason",
          "[model][ablations]") {
  auto refused = [](std::function<void(ModelConfig&)> f) {
    ModelConfig c;
    f(c);
    try {
      validate_section(c, "model");
    } catch (const Error& e) {
      return std::string(e.what());
    }
    return std::string();
  };
  CHECK_THAT(
      refused([](ModelConfig& c) { c.fdi.appearance = false, c.fdi.human = false; }),
      Catch::Contains(
          "config key 'model.fdi' = {appearance: false, human: false}: at least one of the two "
          "branches must stay on"));
  CHECK_THAT(refused([](ModelConfig& c) {
               c.representation = Representation::spc_trilinear, c.fdi.human = false;
             }),
             Catch::Contains("config key 'model.fdi.human' = false: the SPC + trilinear baseline"));
  CHECK_THAT(refused([](ModelConfig& c) { c.grouping.kind = GroupingKind::observation_grid; }),
             Catch::Contains(
                 "config key 'model.transhe.position' = canonical: observation-space grouping"));
  CHECK_THAT(refused([](ModelConfig& c) { c.dparf.nk = 0; }),
             Catch::Contains(
                 "config key 'model.dparf.nk' = 0: must be between 1 and grouping.num_tokens"));
  CHECK(refused([](ModelConfig&) {}).empty());
}

TEST_CASE("a frame with fewer non-empty tokens than Nk is refused naming the setting",
          "[model][ablations]") {
  auto cfg = test::tiny_model_config();
  cfg.dparf.nk = 9;
  auto frame = test::synthetic_frame(300, 24);
  frame.inputs.labels = frame.inputs.labels.remainder(5);  // 5 non-empty clusters out of 24
  TransHuman model(cfg);
  CHECK_THROWS_WITH(model->prepare(frame.inputs, 0.1), Catch::Contains("model.dparf.nk"));
}
