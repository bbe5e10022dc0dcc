// The composed network: parameter counts, gradients, checkpointed chunks, BatchNorm modes.
#include <torch/torch.h>

#include <catch2/catch.hpp>
#include <map>
#include <set>

#include "model/frame_fixture.hpp"
#include "model/transhuman.hpp"
#include "pipeline/pipeline.hpp"
#include "render/volume.hpp"

using namespace th;
using namespace th::model;

namespace {

int64_t count_of(const std::vector<ParameterCount>& counts, const std::string& module) {
  for (const auto& c : counts)
    if (c.module == module) return c.count;
  FAIL("no module " << module);
  return -1;
}

// One training-like step: stratified rendering of the target view's rays, MSE to a random image.
torch::Tensor render_loss(TransHumanImpl& model, const test::SyntheticFrame& frame,
                          int64_t rays_side, int samples, bool checkpoint, int64_t chunk = 4096,
                          int64_t keep_graph_points = 0) {
  RenderConfig rc;
  rc.samples = samples;
  rc.chunk_points = chunk;
  const auto cache = model.prepare(frame.inputs, rc.cull_distance);
  FrameField field(model, cache, chunk, checkpoint, keep_graph_points);
  render::VolumeRenderer renderer(rc);
  const auto rays = test::target_rays(frame, rays_side);
  torch::manual_seed(11);  // same stratification for every call
  const auto out = renderer.render(field, rays, true);
  torch::manual_seed(12);
  return (out.rgb - torch::rand_like(out.rgb)).pow(2).mean();
}

}  // namespace

TEST_CASE("the default configuration has 6,922,244 active parameters (METHOD 3.4)",
          "[model][params]") {
  TransHuman model(ModelConfig{});
  const auto counts = parameter_counts(*model);
  CHECK(count_of(counts, "encoder (ResNet-18 to layer2)") == 683072);
  CHECK(count_of(counts, "reduction + colour") == 74432);
  CHECK(count_of(counts, "ViT") == 5338752);
  CHECK(count_of(counts, "heads (fc_0, FDI, density, colour)") == 825988);
  CHECK(count_of(counts, "total") == 6922244);
}

TEST_CASE("every parameter receives a finite gradient from one training step",
          "[model][gradients]") {
  const auto frame = test::synthetic_frame();
  torch::manual_seed(5);
  TransHuman model(test::tiny_model_config());
  model->train();
  test::center_density(*model, frame);
  const auto loss = render_loss(*model, frame, 12, 16, true);
  loss.backward();
  // The one legitimate exception: the key bias of the view attention (fdi.key0.bias) adds
  // q_v . b to every key view j alike, and the softmax over j ignores it, so its gradient is
  // zero up to rounding (also in the reference network).
  const double key_bias_grad = model->fdi->key0->bias.grad().abs().max().item<double>();
  const double key_weight_grad = model->fdi->key0->weight.grad().abs().max().item<double>();
  CHECK(key_bias_grad <= 1e-6 * key_weight_grad);
  std::vector<std::string> missing, non_finite, zero;
  for (const auto& p : model->named_parameters()) {
    const auto& g = p.value().grad();
    if (!g.defined())
      missing.push_back(p.key());
    else if (!torch::isfinite(g).all().item<bool>())
      non_finite.push_back(p.key());
    else if (g.abs().max().item<double>() == 0 && p.key() != "fdi.key0.bias")
      zero.push_back(p.key());
  }
  std::string names;
  for (const auto& k : missing) names += "\n  no gradient: " + k;
  for (const auto& k : non_finite) names += "\n  non-finite gradient: " + k;
  for (const auto& k : zero) names += "\n  zero gradient: " + k;
  INFO("missing: " << missing.size() << ", non-finite: " << non_finite.size()
                   << ", zero: " << zero.size() << names);
  CHECK(missing.empty());
  CHECK(non_finite.empty());
  CHECK(zero.empty());
}

TEST_CASE("checkpointed chunks give the same loss and gradients as plain autograd",
          "[model][gradients]") {
  const auto frame = test::synthetic_frame();
  torch::manual_seed(6);
  TransHuman model(test::tiny_model_config());
  model->train();
  test::center_density(*model, frame);
  auto grads = [&](bool checkpoint, int64_t chunk) {
    model->zero_grad();
    const auto loss = render_loss(*model, frame, 12, 16, checkpoint, chunk);
    loss.backward();
    std::map<std::string, torch::Tensor> g;
    for (const auto& p : model->named_parameters()) g[p.key()] = p.value().grad().clone();
    return std::pair{loss.item<double>(), g};
  };
  const auto [l1, g1] = grads(false, 1 << 20);
  const auto [l2, g2] = grads(true, 1024);  // several chunks per call
  CHECK(l1 == Approx(l2).epsilon(1e-6));
  for (const auto& [k, g] : g1) {
    INFO(k);
    const double scale = g.abs().max().item<double>();
    CHECK((g - g2.at(k)).abs().max().item<double>() <= 1e-4 * scale + 1e-9);
  }
}

TEST_CASE(
    "train_recompute auto recomputes a field call above its threshold, with the same gradients bit "
    "for bit",
    "[model][gradients][recompute]") {
  torch::set_num_threads(1);
  const auto frame = test::synthetic_frame();
  torch::manual_seed(6);
  TransHuman model(test::tiny_model_config());
  model->train();
  test::center_density(*model, frame);
  // The in-box rays of a 24 x 24 grid, with enough samples for one field call above the
  // threshold under which "auto" keeps the chunks' graphs: 17 or more chunks of 4,096.
  const int64_t side = 24, chunk = 4096;
  const int64_t rays = test::target_rays(frame, side).size();
  REQUIRE(rays > 0);
  const int samples = int(kKeepGraphPoints / rays + 1);
  CAPTURE(rays, samples);
  REQUIRE(rays * samples > kKeepGraphPoints);
  RenderConfig rc;
  auto grads = [&](const char* mode) {
    rc.train_recompute = std::string(mode) == "never"    ? Recompute::never
                         : std::string(mode) == "always" ? Recompute::always
                                                         : Recompute::automatic;
    model->zero_grad();
    render_loss(*model, frame, side, samples, true, chunk, pipeline::keep_graph_points(rc))
        .backward();
    std::map<std::string, torch::Tensor> g;
    for (const auto& p : model->named_parameters()) g[p.key()] = p.value().grad().clone();
    return g;
  };
  // "never" keeps the forward pass's graphs: the reference for the recomputed chunks of
  // "always" and, above the threshold, of "auto".
  const auto never = grads("never"), always = grads("always"), automatic = grads("auto");
  CHECK(pipeline::keep_graph_points(rc) == kKeepGraphPoints);
  size_t zero = 0;
  for (const auto& [k, g] : never) zero += g.abs().max().item<double>() == 0;
  CHECK(zero <= 1);  // fdi.key0.bias (see above): the call trains every other parameter
  for (const auto* other : {&always, &automatic}) {
    size_t differing = 0;
    for (const auto& [k, g] : never) differing += !torch::equal(g, other->at(k));
    CHECK(differing == 0);
  }
}

TEST_CASE("gradients agree with finite differences on a tiny configuration (float64)",
          "[model][gradients]") {
  const auto frame = test::synthetic_frame(120, 10, 2, 16, 7);
  auto cfg = test::tiny_model_config(1);
  cfg.dparf.nk = 3;
  torch::manual_seed(8);
  TransHuman model(cfg);
  model->to(torch::kDouble);
  model->train();
  auto in = frame.inputs;
  for (auto* t : {&in.ref_images, &in.K, &in.R, &in.T, &in.vertices, &in.Rh, &in.Th, &in.A})
    *t = t->to(torch::kDouble);
  auto f = frame;
  f.inputs = in;
  f.target_K = f.target_K.to(torch::kDouble);
  f.target_R = f.target_R.to(torch::kDouble);
  f.target_T = f.target_T.to(torch::kDouble);
  test::center_density(*model, f);
  auto loss_fn = [&] { return render_loss(*model, f, 6, 8, true, 128); };
  model->zero_grad();
  loss_fn().backward();
  // A few entries of every parameter tensor, compared with central differences.
  const double eps = 1e-6;
  int checked = 0, bad = 0, nonzero = 0;
  torch::manual_seed(9);
  for (auto& p : model->named_parameters()) {
    auto flat = p.value().detach().view(-1);
    const auto grad = p.value().grad().view(-1);
    for (int i = 0; i < 2; ++i) {
      const int64_t j = torch::randint(flat.size(0), {1}).item<int64_t>();
      const double x0 = flat[j].item<double>();
      double plus, minus;
      {
        torch::NoGradGuard ng;
        flat[j] = x0 + eps;
        plus = loss_fn().item<double>();
        flat[j] = x0 - eps;
        minus = loss_fn().item<double>();
        flat[j] = x0;
      }
      const double fd = (plus - minus) / (2 * eps), ad = grad[j].item<double>();
      ++checked;
      if (std::abs(fd) > 1e-9) ++nonzero;
      if (std::abs(fd - ad) > 1e-5 + 1e-3 * std::abs(fd)) {
        ++bad;
        UNSCOPED_INFO(p.key() << "[" << j << "]: autograd " << ad << " finite difference " << fd);
      }
    }
  }
  INFO(bad << " of " << checked << " entries disagree; " << nonzero << " non-zero");
  CHECK(bad == 0);
  CHECK(nonzero > checked * 3 / 4);
}

TEST_CASE("BatchNorm uses the reference views' statistics at inference by default",
          "[model][encoder]") {
  const auto frame = test::synthetic_frame();
  EncoderConfig batch_cfg, running_cfg;
  running_cfg.batchnorm = BatchNormStats::running;
  torch::manual_seed(10);
  Encoder batch(batch_cfg, true, 192);
  torch::manual_seed(10);
  Encoder running(running_cfg, true, 192);
  batch->eval();
  running->eval();
  torch::NoGradGuard ng;
  const auto images = frame.inputs.ref_images;
  const auto before = batch->model->bn1->running_mean.clone();
  const auto l0_batch = batch->forward(images).levels[0];
  // Batch statistics: normalised output has ~zero mean per channel before the ReLU's effect;
  // compare with an explicit train-mode batch norm of the same input.
  const auto x = batch->model->conv1(images);
  const auto expected = torch::relu(torch::batch_norm(
      x, batch->model->bn1->weight, batch->model->bn1->bias, {}, {}, true, 0.1, 1e-5, false));
  CHECK((l0_batch - expected).abs().max().item<double>() < 1e-5);
  CHECK(torch::equal(before, batch->model->bn1->running_mean));  // inference does not update them
  const auto l0_running = running->forward(images).levels[0];
  const auto expected_running = torch::relu(torch::batch_norm(
      x, running->model->bn1->weight, running->model->bn1->bias, running->model->bn1->running_mean,
      running->model->bn1->running_var, false, 0.1, 1e-5, false));
  CHECK((l0_running - expected_running).abs().max().item<double>() < 1e-5);
  CHECK((l0_running - l0_batch).abs().max().item<double>() > 1e-3);
}

TEST_CASE(
    "model.transhe.dim sets the width of the painted features, and the network builds and renders "
    "with it",
    "[model][config]") {
  const auto frame = test::synthetic_frame();
  auto cfg = test::tiny_model_config();
  cfg.transhe.dim = 96;
  cfg.transhe.pe_freqs = 16;  // 6 x pe_freqs = dim
  cfg.transhe.mlp_dim = 192;
  torch::manual_seed(11);
  TransHuman model(cfg);
  CHECK(model->encoder->reduction_layer->weight.size(0) == 96);
  torch::NoGradGuard ng;
  const auto cache = model->prepare(frame.inputs, 0.1);
  const auto pts = frame.inputs.vertices.narrow(0, 0, 16);
  const auto raw = model->forward(cache, pts, torch::randn({16, 3}));
  CHECK(raw.sizes() == torch::IntArrayRef({16, 4}));
  CHECK(torch::isfinite(raw).all().item<bool>());
}
