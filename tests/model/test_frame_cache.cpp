// The per-frame state's leaf list cannot miss a tensor: the checkpointed backward pass swaps
// the tensors that FrameCache::visit shows for leaves of a graph of its own, so a stage tensor
// that carries per-frame history but is not visited would reach the encoder or the transformer
// from inside the recomputation. This walks the autograd graph of the per-point network, for
// every form of every stage, and fails when it reaches per-frame work other than through a
// visited tensor.
#include <torch/csrc/autograd/function.h>
#include <torch/csrc/autograd/functions/accumulate_grad.h>
#include <torch/torch.h>

#include <catch2/catch.hpp>
#include <functional>
#include <set>
#include <string>
#include <vector>

#include "model/frame_fixture.hpp"
#include "model/transhuman.hpp"

using namespace th;
using namespace th::model;

namespace {

using Node = torch::autograd::Node;

// The nodes of `output`'s graph created before `boundary` (per-frame work) that are reached
// without passing through one of `stage` (the visited tensors' grad_fns). Parameters
// (AccumulateGrad) are leaves and may be reached directly.
std::vector<std::string> unvisited_frame_nodes(const torch::Tensor& output,
                                               const std::set<const Node*>& stage,
                                               uint64_t boundary) {
  std::vector<std::string> found;
  std::set<const Node*> seen;
  std::vector<Node*> todo{output.grad_fn().get()};
  while (!todo.empty()) {
    Node* node = todo.back();
    todo.pop_back();
    if (!node || !seen.insert(node).second || stage.count(node)) continue;
    if (dynamic_cast<torch::autograd::AccumulateGrad*>(node)) continue;
    if (node->sequence_nr() < boundary) {
      found.push_back(node->name());
      continue;
    }
    for (const auto& edge : node->next_edges()) todo.push_back(edge.function.get());
  }
  return found;
}

// A node made now: every node of the graph made before it has a smaller sequence number.
uint64_t sequence_now() {
  const auto x = torch::ones({1}, torch::requires_grad());
  return (x * 2).grad_fn()->sequence_nr();
}

struct Variant {
  const char* name;
  void (*apply)(ModelConfig&);
};

}  // namespace

TEST_CASE("every per-frame tensor that the per-point network reads is visited, in every form",
          "[model][frame_cache]") {
  const auto frame = test::synthetic_frame();
  const std::vector<Variant> variants{
      {"default", [](ModelConfig&) {}},
      {"w/o a", [](ModelConfig& c) { c.fdi.appearance = false; }},
      {"w/o h", [](ModelConfig& c) { c.fdi.human = false; }},
      {"w/o RGB", [](ModelConfig& c) { c.fdi.raw_rgb = false; }},
      {"w/o TransHE", [](ModelConfig& c) { c.transhe.enabled = false; }},
      {"absolute coordinates", [](ModelConfig& c) { c.dparf.coordinate = Coordinate::absolute; }},
      {"no coordinates", [](ModelConfig& c) { c.dparf.coordinate = Coordinate::none; }},
      {"SPC baseline",
       [](ModelConfig& c) {
         c.representation = Representation::spc_trilinear, c.spc.voxel_size = 0.1,
         c.spc.channels = 8;
       }},
  };
  for (const auto& v : variants) {
    DYNAMIC_SECTION(v.name) {
      auto cfg = test::tiny_model_config();
      v.apply(cfg);
      torch::manual_seed(21);
      TransHuman model(cfg);
      model->train();
      auto cache = model->prepare(frame.inputs, 0.1);  // under autograd, as training prepares
      std::set<const Node*> stage;
      int64_t with_history = 0;
      cache.visit([&](torch::Tensor& t, torch::Tensor*) {
        if (t.defined() && t.grad_fn()) stage.insert(t.grad_fn().get()), ++with_history;
      });
      CHECK(with_history > 0);
      const uint64_t boundary = sequence_now();
      const auto pts = frame.inputs.vertices.narrow(0, 0, 40) + 0.03 * torch::randn({40, 3});
      const auto raw = model->forward(cache, pts, torch::randn({40, 3}));
      const auto missed = unvisited_frame_nodes(raw, stage, boundary);
      std::string names;
      for (const auto& n : missed) names += " " + n;
      INFO("per-frame nodes reached around the visited tensors:" << names);
      CHECK(missed.empty());

      // The walk sees a tensor left out: without the first visited tensor that the per-point
      // network reads, it reaches that tensor's per-frame history.
      bool detected = false;
      for (const Node* skipped : stage) {
        auto fewer = stage;
        fewer.erase(skipped);
        if (!unvisited_frame_nodes(raw, fewer, boundary).empty()) {
          detected = true;
          break;
        }
      }
      CHECK(detected);
    }
  }
}
