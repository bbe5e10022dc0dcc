// The network as it runs (model/transhuman.cpp, with its kernels) against the whole network written
// independently in PyTorch from docs/METHOD.md (tests/python/model_reference.py network), for the
// default configuration, every row of configs/ablations and the model switches that have no row
// there: the same weights, frame and points give the same density and colour per point
// (inference) and the same parameter gradients (training: train mode, GradMode on, the
// checkpointed FrameField the renderer trains through). The model runs with its CPU kernels, and
// again with their LibTorch forms, the arithmetic it runs on a GPU (model/kernels/forms.hpp).
#include <torch/torch.h>
#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <catch2/catch.hpp>
#include <cstdio>
#include <filesystem>
#include <map>
#include <memory>
#include <optional>
#include <set>
#include <string>
#include <vector>

#include "core/config_io.hpp"
#include "model/frame_fixture.hpp"
#include "model/kernels/forms.hpp"
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

// The reference's inputs: the model's weights and the switches of its configuration, the frame.
void add_model_and_frame(test::PythonReference& py, const TransHumanImpl& model,
                         const FrameInputs& in) {
  for (const auto& p : model.named_parameters()) py.add("P_" + p.key(), p.value());
  for (const auto& b : model.named_buffers())
    if (b.key().find("num_batches") == std::string::npos) py.add("B_" + b.key(), b.value());
  const auto& c = model.config();
  const int64_t nt = in.num_tokens > 0 ? in.num_tokens : in.labels.max().item<int64_t>() + 1;
  for (const auto& [name, value] : std::vector<std::pair<std::string, double>>{
           {"appearance", c.fdi.appearance},
           {"human", c.fdi.human},
           {"spc", c.representation == Representation::spc_trilinear},
           {"transhe", c.transhe.enabled},
           {"position_observation", c.transhe.position == TokenPosition::observation},
           {"mean_over_visible", c.grouping.mean_over == MeanOver::visible},
           {"pe_scale", c.transhe.pe_scale},
           {"transhe_pe_freqs", c.transhe.pe_freqs},
           {"transhe_fused", c.transhe.pe_rounding == PeRounding::fused},
           {"heads", c.transhe.heads},
           {"nk", c.dparf.nk},
           {"temperature", c.dparf.softmax_temperature},
           {"dparf_pe_freqs", c.dparf.pe_freqs},
           {"dparf_fused", c.dparf.pe_rounding == PeRounding::fused},
           {"coordinate", c.dparf.coordinate == Coordinate::relative   ? 0
                          : c.dparf.coordinate == Coordinate::absolute ? 1
                                                                       : 2},
           {"batch_stats", c.encoder.batchnorm == BatchNormStats::batch},
           {"voxel_size", c.spc.voxel_size},
           {"num_tokens", double(nt)}})
    py.add("cfg_" + name, torch::tensor({value}, torch::kDouble));
  const auto f32 = [](const torch::Tensor& t) { return t.to(torch::kFloat); };
  py.add("ref_images", f32(in.ref_images));
  py.add("K", f32(in.K));
  py.add("R", f32(in.R));
  py.add("T", f32(in.T));
  py.add("vertices", f32(in.vertices));
  py.add("Rh", f32(in.Rh));
  py.add("Th", f32(in.Th));
  py.add("A", f32(in.A));
  py.add("canonical", in.canonical.to(torch::kDouble));
  py.add("visibility", in.visibility.to(torch::kLong));
  py.add("labels", in.labels);
}

// What the model computes: raw outputs at inference, and in training mode (the checkpointed
// FrameField the renderer trains through) the parameters' gradients of sum(sigma w_3) +
// sum(rgb w_rgb coloured), colour where sigma_raw > 0 (elsewhere it has no compositing weight).
struct Ours {
  torch::Tensor raw, coloured;
  std::map<std::string, torch::Tensor> grads;
};

Ours evaluate(TransHumanImpl& model, const FrameInputs& in, const torch::Tensor& pts,
              const torch::Tensor& dirs, const torch::Tensor& w) {
  Ours o;
  {
    model.eval();
    torch::NoGradGuard no_grad;
    o.raw = model.forward(model.prepare(in, 0.1), pts, dirs);
  }
  model.train();
  model.zero_grad();
  const auto cache = model.prepare(in, 0.1);
  FrameField field(model, cache, /*chunk_points=*/24, /*checkpoint=*/true);
  const auto raw = field.raw(pts, dirs);
  o.coloured = (raw.select(1, 3) > 0).detach().to(raw.scalar_type()).unsqueeze(1);
  ((raw.select(1, 3) * w.select(1, 3)).sum() +
   (raw.narrow(1, 0, 3) * w.narrow(1, 0, 3) * o.coloured).sum())
      .backward();
  for (const auto& p : model.named_parameters())
    if (p.value().grad().defined()) o.grads[p.key()] = p.value().grad().clone();
  return o;
}

struct Comparison {
  double raw = 0, raw_scale = 0;  // max |raw difference| at inference, max |raw| of the reference
  double grad = 0;                // worst parameter: max |gradient difference| / max |gradient|
  std::string worst;              // that parameter
};

// Ours against the reference's outputs; `k` names the reference's gradients of our mask.
Comparison compare(const Ours& ours, const std::map<std::string, torch::Tensor>& ref,
                   const std::string& k) {
  Comparison c;
  c.raw = max_abs(ours.raw, ref.at("raw"));
  c.raw_scale = ref.at("raw").abs().max().item<double>();
  size_t matched = 0;
  for (const auto& [name, g] : ours.grads) {
    const auto it = ref.find(k + "G_" + name);
    INFO(name);
    REQUIRE(it != ref.end());  // a gradient the reference does not have
    ++matched;
    const double scale = it->second.abs().max().item<double>();
    // fdi.key0.bias: the softmax over the key views ignores it, its gradient is rounding only.
    if (scale == 0 || name == "fdi.key0.bias") continue;
    const double rel = max_abs(g, it->second) / scale;
    if (rel > c.grad) c.grad = rel, c.worst = name;
  }
  size_t expected = 0;  // and none the model lacks
  for (const auto& r : ref) expected += r.first.rfind(k + "G_", 0) == 0;
  CHECK(matched == expected);
  return c;
}

struct Setup {
  TransHuman model{nullptr};
  test::SyntheticFrame frame;
  torch::Tensor pts, dirs;
};

// The row's model, its frame and points (the same for the same configuration).
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

// The row's model in one form (the CPU kernels, or their LibTorch forms), on its points moved by
// `move` (metres, random directions).
Ours evaluate_form(const ModelConfig& cfg, bool libtorch, double move, torch::Tensor* pts_out,
                   torch::Tensor* w_out) {
  auto s = setup(cfg);  // a fresh model: training mode moves BatchNorm's statistics
  torch::manual_seed(12);
  const auto pts = s.pts + move * torch::randn_like(s.pts);
  torch::manual_seed(11);
  const auto w = torch::randn({pts.size(0), 4});
  if (pts_out) *pts_out = pts;
  if (w_out) *w_out = w;
  std::optional<kernels::LibTorchForms> forms;
  if (libtorch) forms.emplace();
  return evaluate(*s.model, s.frame.inputs, pts, s.dirs, w);
}

}  // namespace

// Every row in both forms: the CPU kernels, and what runs on a GPU, run on the CPU (every
// operation in its LibTorch form: no readout windows, no CPU kernel, no gradient sink). Rows whose
// model keys equal an earlier row's (those that change rendering or training only) are run once.
// One Python process answers every row.
// Gradients jump at ReLU's kink, so a unit whose pre-activation lies within rounding of zero can
// take the other side in other arithmetic and move one channel's gradient by far more than
// rounding. Such a point set is measure zero: where the gradients differ, the comparison is made
// again at points moved by 1 mm, and there they must agree; a wrong formula differs at both.
TEST_CASE("the network equals the Python reference in every ablation, in both forms",
          "[model][network]") {
  const auto model_keys = [](const ModelConfig& c) { return YAML::Dump(config::to_tree(c)); };
  struct Case {
    std::string name;
    ModelConfig cfg;
    std::unique_ptr<test::PythonReference> py;
    Ours ours[2];  // kernels, LibTorch forms
  };
  std::vector<Case> cases;
  std::set<std::string> seen;
  // The reference's inputs for the row's model (as set up, before any training step) on `pts`.
  const auto reference = [](const std::string& name, const ModelConfig& cfg,
                            const torch::Tensor& pts, const torch::Tensor& w) {
    auto py = std::make_unique<test::PythonReference>("network_" + name);
    const auto s = setup(cfg);
    add_model_and_frame(*py, *s.model, s.frame.inputs);
    py->add("pts", pts);
    py->add("dirs", s.dirs);
    py->add("w", w);
    return py;
  };
  for (const auto& row : rows()) {
    if (!seen.insert(model_keys(row.model)).second) continue;
    Case c{row.name, row.model, nullptr, {}};
    torch::Tensor pts, w;
    c.ours[0] = evaluate_form(row.model, false, 0, &pts, &w);
    c.ours[1] = evaluate_form(row.model, true, 0, nullptr, nullptr);
    c.py = reference(row.name, row.model, pts, w);
    c.py->add("coloured0", c.ours[0].coloured);
    c.py->add("coloured1", c.ours[1].coloured);
    cases.push_back(std::move(c));
  }
  std::vector<test::PythonReference*> all;
  for (auto& c : cases) all.push_back(c.py.get());
  test::PythonReference::run_all("network", all);

  for (auto& c : cases) {
    const auto ref = c.py->outputs();
    for (int form : {0, 1}) {
      INFO(c.name << (form ? " (LibTorch forms)" : " (CPU kernels)"));
      auto r = compare(c.ours[form], ref, std::to_string(form));
      const auto report = [&](const char* at) {
        std::printf(
            "%s vs reference %-26s %-5s max|raw diff| %.2e (max|raw| %.2f)  grad rel %.2e (%s)\n",
            form ? "LibTorch" : "kernels ", c.name.c_str(), at, r.raw, r.raw_scale, r.grad,
            r.worst.c_str());
      };
      report("");
      CHECK(r.raw <= 2e-6 * (1 + r.raw_scale));
      if (r.grad > 1e-5) {
        torch::Tensor pts, w;
        const auto moved = evaluate_form(c.cfg, form == 1, 1e-3, &pts, &w);
        auto py = reference(c.name + "_moved", c.cfg, pts, w);
        py->add("coloured0", moved.coloured);
        r = compare(moved, py->run("network"), "0");
        report("moved");
        CHECK(r.raw <= 2e-6 * (1 + r.raw_scale));
      }
      INFO("worst gradient: " << r.worst);
      CHECK(r.grad <= 1e-5);
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
