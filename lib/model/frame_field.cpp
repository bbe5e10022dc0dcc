// FrameField: a prepared frame's chunks of points, with recomputation in the backward pass.
#include <torch/csrc/autograd/custom_function.h>

#include <algorithm>

#include "model/kernels/forms.hpp"
#include "model/transhuman.hpp"
#include "render/chunks.hpp"

namespace th::model {

namespace {

// The frame's tensors that carry a gradient, as leaves of a graph of their own (the same
// tensors, in the same order, as the inputs of CheckpointedChunks::forward); tables read by
// weighted_gather get a gradient sink where the CPU kernels run.
struct LeafFrame {
  FrameCache cache;
  std::vector<torch::Tensor> leaves, sinks;

  explicit LeafFrame(const FrameCache& frame) : cache(frame) {
    cache.visit([&](torch::Tensor& t, torch::Tensor* sink) {
      if (!t.defined() || !t.requires_grad()) return;
      t = t.detach().requires_grad_(true);
      leaves.push_back(t);
      sinks.emplace_back();
      if (sink && kernels::cpu_kernels(t.device())) sinks.back() = *sink = torch::zeros_like(t);
    });
  }
  // The gradients of the leaves (sinks added), one per leaf.
  torch::autograd::variable_list grads() const {
    torch::autograd::variable_list out;
    for (size_t i = 0; i < leaves.size(); ++i) {
      auto g = leaves[i].grad();
      if (sinks[i].defined()) g = g.defined() ? g + sinks[i] : sinks[i];
      out.push_back(g.defined() ? g : torch::zeros_like(leaves[i]));
    }
    return out;
  }
};

struct ChunkJob : torch::CustomClassHolder {
  TransHumanImpl* model = nullptr;
  FrameCache cache;
  int64_t chunk = 0;
  bool keep_graph = false;
  // keep_graph: the leaf frame and each chunk's output, with its graph, from the forward pass.
  std::unique_ptr<LeafFrame> kept;
  std::vector<torch::Tensor> outputs;
};

torch::Tensor forward_chunks(TransHumanImpl& model, const FrameCache& cache,
                             const torch::Tensor& pts, const torch::Tensor& dirs, int64_t chunk,
                             bool density_first) {
  return render::cat_chunks(pts.size(0), chunk, [&](int64_t b, int64_t e) {
    const auto p = pts.slice(0, b, e), d = dirs.slice(0, b, e);
    return density_first ? model.forward_density_first(cache, p, d) : model.forward(cache, p, d);
  });
}

// Forward without a graph; backward recomputes chunk by chunk with leaf copies of the frame
// tensors, accumulates their gradients and hands them to the outer graph (the encoder, ViT and
// the folded weights), while parameters used per point accumulate into .grad directly.
// Colour is evaluated only where sigma_raw > 0: elsewhere the compositing weight is 0, so
// neither the image nor any gradient changes. With job->keep_graph the forward pass builds the
// chunks' graphs on the leaf frame already and the backward pass only runs them, chunk by chunk
// in the same order: the same gradients, one forward less.
struct CheckpointedChunks : torch::autograd::Function<CheckpointedChunks> {
  static torch::Tensor forward(torch::autograd::AutogradContext* ctx, torch::TensorList frame,
                               const torch::Tensor& pts, const torch::Tensor& dirs,
                               c10::intrusive_ptr<ChunkJob> job) {
    ctx->save_for_backward({pts, dirs});
    ctx->saved_data["job"] = c10::IValue::make_capsule(job);
    if (!job->keep_graph)
      return forward_chunks(*job->model, job->cache, pts, dirs, job->chunk, true);
    torch::AutoGradMode enable(true);
    job->kept = std::make_unique<LeafFrame>(job->cache);
    return render::cat_chunks(pts.size(0), job->chunk, [&](int64_t b, int64_t e) {
      job->outputs.push_back(job->model->forward_density_first(job->kept->cache, pts.slice(0, b, e),
                                                               dirs.slice(0, b, e)));
      return job->outputs.back().detach();
    });
  }

  static torch::autograd::variable_list backward(torch::autograd::AutogradContext* ctx,
                                                 torch::autograd::variable_list grad_out) {
    auto job = c10::static_intrusive_pointer_cast<ChunkJob>(ctx->saved_data["job"].toCapsule());
    const auto saved = ctx->get_saved_variables();
    const auto &pts = saved[0], &dirs = saved[1];
    torch::AutoGradMode enable(true);
    const auto& g = grad_out[0];
    const int64_t n = pts.size(0);
    torch::autograd::variable_list grads;
    if (job->keep_graph) {
      TORCH_CHECK(job->kept && job->outputs.size() ==
                                   size_t(std::max<int64_t>(1, (n + job->chunk - 1) / job->chunk)),
                  "the kept per-point graphs were already used (a second backward pass)");
      size_t i = 0;
      render::for_each_chunk(n, job->chunk, [&](int64_t b, int64_t e) {
        torch::autograd::backward({job->outputs[i++]}, {g.slice(0, b, e)});
      });
      grads = job->kept->grads();
      job->outputs.clear();
      job->kept.reset();
    } else {
      LeafFrame leaf(job->cache);
      render::for_each_chunk(n, job->chunk, [&](int64_t b, int64_t e) {
        const auto raw =
            job->model->forward_density_first(leaf.cache, pts.slice(0, b, e), dirs.slice(0, b, e));
        torch::autograd::backward({raw}, {g.slice(0, b, e)});
      });
      grads = leaf.grads();
    }
    grads.emplace_back();  // pts
    grads.emplace_back();  // dirs
    grads.emplace_back();  // job
    return grads;
  }
};

}  // namespace

FrameField::FrameField(TransHumanImpl& model, const FrameCache& cache, int64_t chunk_points,
                       bool checkpoint, int64_t keep_graph_points)
    : model_(model),
      cache_(cache),
      chunk_(chunk_points),
      checkpoint_(checkpoint),
      keep_graph_points_(keep_graph_points) {}

torch::Tensor FrameField::raw(const torch::Tensor& pts, const torch::Tensor& dirs) {
  if (!checkpoint_ || !torch::GradMode::is_enabled())
    return forward_chunks(model_, cache_, pts, dirs, chunk_, false);
  auto job = c10::make_intrusive<ChunkJob>();
  job->model = &model_;
  job->cache = cache_;
  job->chunk = chunk_;
  job->keep_graph = pts.size(0) <= keep_graph_points_;
  std::vector<torch::Tensor> frame;
  job->cache.visit([&](torch::Tensor& t, torch::Tensor*) {
    if (t.defined() && t.requires_grad()) frame.push_back(t);
  });
  return CheckpointedChunks::apply(torch::TensorList(frame), pts, dirs, job);
}

torch::Tensor FrameField::raw_density_first(const torch::Tensor& pts, const torch::Tensor& dirs) {
  torch::NoGradGuard no_grad;
  return forward_chunks(model_, cache_, pts, dirs, chunk_, true);
}

}  // namespace th::model
