// The plain forward pass of METHOD 3 (model/network.hpp) against the model's own forms, for
// the default configuration, every row of configs/ablations and the model switches that have no
// row there: the same weights and frame give the same density and colour per point (inference)
// and the same parameter gradients (training: train mode, GradMode on, the checkpointed
// FrameField the renderer trains through). The model runs with its CPU kernels, and again with
// their LibTorch forms, the arithmetic it runs on a GPU (model/kernels/forms.hpp).
#include <torch/torch.h>
#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <catch2/catch.hpp>
#include <cstdio>
#include <filesystem>
#include <map>
#include <string>
#include <vector>

#include "core/config_io.hpp"
#include "model/frame_fixture.hpp"
#include "model/kernels/forms.hpp"
#include "model/network.hpp"
#include "model/transhuman.hpp"

using namespace th;
using namespace th::model;
using test::max_abs;

namespace {

// Tiny sizes on top of each row's configuration.
const std::vector<std::string> kTiny = {"model.transhe.depth=2", "model.spc.voxel_size=0.05",
                                        "model.spc.channels=16"};

struct Row {
  std::string name;
  ModelConfig model;
};

// configs/default.yaml, every configs/ablations/<row>.yaml (sorted), and the switches of
// ModelConfig that no row sets.
std::vector<Row> rows() {
  auto load = [](const std::string& file, std::vector<std::string> extra = {}) {
    extra.insert(extra.begin(), kTiny.begin(), kTiny.end());
    return config::load<Config>(file, extra).model;
  };
  std::vector<Row> out{{"default", load("configs/default.yaml")}};
  std::vector<std::string> names;
  for (const auto& entry : std::filesystem::directory_iterator("configs/ablations")) {
    const auto stem = entry.path().stem().string();
    if (entry.path().extension() == ".yaml" && stem[0] != '_') names.push_back(stem);
  }
  std::sort(names.begin(), names.end());
  for (const auto& n : names) out.push_back({n, load("configs/ablations/" + n + ".yaml")});
  out.push_back(
      {"transhe_disabled", load("configs/default.yaml", {"model.transhe.enabled=false"})});
  out.push_back(
      {"mean_over_visible", load("configs/default.yaml", {"model.grouping.mean_over=visible"})});
  out.push_back({"pe_rounding_separate",
                 load("configs/default.yaml",
                      {"model.transhe.pe_rounding=separate", "model.dparf.pe_rounding=separate"})});
  out.push_back(
      {"batchnorm_running", load("configs/default.yaml", {"model.encoder.batchnorm=running"})});
  return out;
}

// Voxel-grid labels (the grid groupings of METHOD 2.5): many voxel ids stay empty.
torch::Tensor grid_labels(const torch::Tensor& points, double cell) {
  const auto p = points.to(torch::kDouble);
  const auto c = ((p - std::get<0>(p.min(0))) / cell).floor().to(torch::kLong);
  const auto dims = std::get<0>(c.max(0)) + 1;
  return (c.select(1, 2) * dims[1] + c.select(1, 1)) * dims[0] + c.select(1, 0);
}

// The row's frame: 24 tokens where the row keeps the default Nt, its own Nt otherwise, and the
// labels of its grouping.
test::SyntheticFrame frame_for(ModelConfig& cfg) {
  const int64_t tokens =
      cfg.grouping.num_tokens == ModelConfig{}.grouping.num_tokens ? 24 : cfg.grouping.num_tokens;
  cfg.grouping.num_tokens = static_cast<int>(tokens);
  auto frame = test::synthetic_frame(std::max<int64_t>(300, 2 * tokens), tokens);
  auto& in = frame.inputs;
  if (cfg.grouping.kind != GroupingKind::canonical_kmeans) {
    const bool posed = cfg.grouping.kind == GroupingKind::observation_grid;
    in.labels = grid_labels(posed ? in.vertices : in.canonical, 0.12);
    in.num_tokens = in.labels.max().item<int64_t>() + 1;
  }
  return frame;
}

struct Comparison {
  double raw = 0, raw_scale = 0;  // max |raw difference| at inference, max |raw| of the plain pass
  double grad = 0;                // worst parameter: max |gradient difference| / max |gradient|
  std::string worst;              // that parameter
};

// The model (weights as given) against the plain pass on the row's frame.
Comparison compare(TransHumanImpl& model, const test::SyntheticFrame& frame,
                   const torch::Tensor& pts, const torch::Tensor& dirs) {
  const auto& in = frame.inputs;
  Comparison c;
  {
    model.eval();
    torch::NoGradGuard no_grad;
    const auto plain = network_forward(model, in, pts, dirs).raw();
    c.raw = max_abs(model.forward(model.prepare(in, 0.1), pts, dirs), plain);
    c.raw_scale = plain.abs().max().item<double>();
  }
  // Training: sigma everywhere, rgb where sigma_raw > 0 (the checkpointed field computes colour
  // only there; elsewhere it has no compositing weight).
  model.train();
  torch::manual_seed(11);
  const auto w = torch::randn({pts.size(0), 4});
  auto loss = [&](const torch::Tensor& raw, const torch::Tensor& coloured) {
    return (raw.select(1, 3) * w.select(1, 3)).sum() +
           (raw.narrow(1, 0, 3) * w.narrow(1, 0, 3) * coloured).sum();
  };
  auto grads = [&] {
    std::map<std::string, torch::Tensor> g;
    for (const auto& p : model.named_parameters())
      g[p.key()] = p.value().grad().defined() ? p.value().grad().clone() : torch::Tensor();
    return g;
  };
  model.zero_grad();
  const auto cache = model.prepare(in, 0.1);
  FrameField field(model, cache, /*chunk_points=*/24, /*checkpoint=*/true);
  const auto raw = field.raw(pts, dirs);
  const auto coloured = (raw.select(1, 3) > 0).detach().to(raw.scalar_type()).unsqueeze(1);
  loss(raw, coloured).backward();
  const auto g_model = grads();
  model.zero_grad();
  loss(network_forward(model, in, pts, dirs).raw(), coloured).backward();
  const auto g_plain = grads();
  for (const auto& [name, g] : g_plain) {
    const auto& gm = g_model.at(name);
    INFO(name);
    REQUIRE(g.defined() == gm.defined());
    if (!g.defined()) continue;
    const double scale = g.abs().max().item<double>();
    // fdi.key0.bias: the softmax over the key views ignores it, its gradient is rounding only.
    if (scale == 0 || name == "fdi.key0.bias") continue;
    const double rel = max_abs(g, gm) / scale;
    if (rel > c.grad) c.grad = rel, c.worst = name;
  }
  return c;
}

struct Setup {
  TransHuman model{nullptr};
  test::SyntheticFrame frame;
  torch::Tensor pts, dirs;
};

// The row's model, its frame and points.
Setup setup(ModelConfig cfg) {
  Setup s;
  s.frame = frame_for(cfg);
  torch::manual_seed(3);
  s.model = TransHuman(cfg);
  test::center_density(*s.model, s.frame);  // about half the points have density
  torch::manual_seed(4);
  const auto& v = s.frame.inputs.vertices;
  s.pts = v.narrow(0, 0, 64) + 0.05 * torch::randn({64, 3});
  s.dirs = torch::randn({64, 3});
  return s;
}

}  // namespace

TEST_CASE("the plain network pass equals the model with its METHOD 9 shortcuts, in every ablation",
          "[model][network]") {
  for (const auto& row : rows()) {
    DYNAMIC_SECTION(row.name) {
      auto s = setup(row.model);
      const auto c = compare(*s.model, s.frame, s.pts, s.dirs);
      std::printf(
          "plain vs shortcut %-26s max|raw diff| %.2e (max|raw| %.2f)  grad rel %.2e (%s)\n",
          row.name.c_str(), c.raw, c.raw_scale, c.grad, c.worst.c_str());
      INFO("worst gradient: " << c.worst);
      CHECK(c.raw <= 1e-6);
      CHECK(c.grad <= 1e-5);
    }
  }
}

// What runs on a GPU, run on the CPU: every kernel family in its LibTorch form (no readout
// windows, no CPU kernel, no gradient sink).
// Gradients jump at ReLU's kink, so a unit whose pre-activation lies within rounding of zero can
// take the other side in other arithmetic and move one channel's gradient by far more than
// rounding (seen with these rows' data in one row of fdi.fc_2). Such a point set is
// measure zero: where the gradients differ, the comparison is made again at points moved by 1 mm,
// and there they must agree; a wrong formula differs at both.
TEST_CASE("the plain network pass equals the model in its LibTorch forms, in every ablation",
          "[model][network]") {
  for (const auto& row : rows()) {
    DYNAMIC_SECTION(row.name) {
      auto s = setup(row.model);
      kernels::LibTorchForms libtorch_forms;
      CHECK(std::string(s.model->plan(false, torch::kCPU).pixel_form()) != "readout windows");
      auto c = compare(*s.model, s.frame, s.pts, s.dirs);
      auto report = [&](const char* at) {
        std::printf(
            "plain vs LibTorch %-26s %-7s max|raw diff| %.2e (max|raw| %.2f)  grad rel "
            "%.2e (%s)\n",
            row.name.c_str(), at, c.raw, c.raw_scale, c.grad, c.worst.c_str());
      };
      report("");
      CHECK(c.raw <= 1e-6);
      if (c.grad > 1e-5) {
        torch::manual_seed(12);
        c = compare(*s.model, s.frame, s.pts + 1e-3 * torch::randn_like(s.pts), s.dirs);
        report("moved");
        CHECK(c.raw <= 1e-6);
      }
      INFO("worst gradient: " << c.worst);
      CHECK(c.grad <= 1e-5);
    }
  }
}

// Each ablation changes what the network computes: the row's model, given the full model's
// weights wherever a parameter has the same name and shape, and the full model evaluate the same
// points, each on the frame of its own setting (the rows of token groups and Nt change the
// frame's labels, the others the network); their outputs differ. A row whose switch changed nothing
// would give the same outputs bit for bit (checked on the full model against a copy of itself).
// Rows that change no model key (samples, losses, training) are left to their own tests.
TEST_CASE("every ablation changes the network's function", "[model][network][ablations]") {
  const auto all = rows();
  const auto full_it =
      std::find_if(all.begin(), all.end(), [](const Row& r) { return r.name == "full"; });
  REQUIRE(full_it != all.end());
  const auto model_keys = [](const ModelConfig& c) { return YAML::Dump(config::to_tree(c)); };
  for (const auto& row : all) {
    if (row.name == "default" || row.name == "full") continue;
    if (model_keys(row.model) == model_keys(full_it->model)) continue;  // not a model ablation
    DYNAMIC_SECTION(row.name) {
      auto s = setup(row.model);  // the row's model, frame and points
      auto full_cfg = full_it->model;
      const auto full_frame = frame_for(full_cfg);
      torch::manual_seed(3);
      TransHuman full(full_cfg);
      int64_t shared = 0;
      {
        torch::NoGradGuard no_grad;
        auto source = full->named_parameters();
        for (auto& p : s.model->named_parameters()) {
          const auto* q = source.find(p.key());
          if (q && q->sizes() == p.value().sizes()) p.value().copy_(*q), ++shared;
        }
      }
      CHECK(shared > 0);
      full->eval();
      s.model->eval();
      torch::NoGradGuard no_grad;
      auto raw_of = [&](TransHumanImpl& m, const test::SyntheticFrame& f) {
        return m.forward(m.prepare(f.inputs, 0.1), s.pts, s.dirs);
      };
      const auto a = raw_of(*full, full_frame), b = raw_of(*s.model, s.frame);
      const double diff = max_abs(a, b);
      std::printf("ablation %-26s %3lld shared parameters  max|raw - full's| %.3e\n",
                  row.name.c_str(), static_cast<long long>(shared), diff);
      CHECK(diff > 1e-6 * (1 + a.abs().max().item<double>()));
    }
  }
  // The check can fail: the full model against a copy of its own weights gives zero.
  auto s = setup(full_it->model);
  torch::manual_seed(3);
  TransHuman copy(s.model->config());
  {
    torch::NoGradGuard no_grad;
    auto source = s.model->named_parameters();
    for (auto& p : copy->named_parameters()) p.value().copy_(source[p.key()]);
  }
  s.model->eval();
  copy->eval();
  torch::NoGradGuard no_grad;
  CHECK(max_abs(s.model->forward(s.model->prepare(s.frame.inputs, 0.1), s.pts, s.dirs),
                copy->forward(copy->prepare(s.frame.inputs, 0.1), s.pts, s.dirs)) == 0);
}
