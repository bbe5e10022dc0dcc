#include "model/transhuman.hpp"

#include <spdlog/spdlog.h>
#include <torch/csrc/autograd/custom_function.h>

#include <algorithm>
#include <limits>

#include "core/error.hpp"
#include "geometry/camera.hpp"
#include "model/kernels/forms.hpp"
#include "model/positional_encoding.hpp"
#include "model/pretrained.hpp"
#include "render/body_distance.hpp"
#include "render/chunks.hpp"

namespace th::model {

TransHumanImpl::TransHumanImpl(const ModelConfig& config) : config_(config) {
  encoder =
      register_module("encoder", Encoder(config.encoder, config.fdi.raw_rgb, config.transhe.dim));
  if (!config.encoder.pretrained.empty()) {
    load_pretrained_encoder(*encoder, config.encoder.pretrained);
    spdlog::info("encoder: ImageNet ResNet-18 weights from {}", config.encoder.pretrained);
  } else {
    spdlog::info("encoder: random initialisation (model.encoder.pretrained is empty)");
  }
  if (config.fdi.human) human = register_module("human", make_human_representation(config));
  fdi = register_module("fdi", FDI(config.fdi, encoder->pixel_channels()));
  heads = register_module("heads", Heads(config.fdi.appearance, encoder->pixel_channels()));
}

void TransHumanImpl::set_profile(render::Profile* profile) {
  profile_ = profile;
  plans_[0] = plans_[1] = nullptr;
}

void TransHumanImpl::set_products(const Products& products) {
  products_ = products;
  plans_[0] = plans_[1] = nullptr;
}

const Plan& TransHumanImpl::plan(bool training, const torch::Device& device) {
  auto& plan = plans_[training ? 1 : 0];
  const bool cpu_kernels = kernels::cpu_kernels(device);
  if (!plan || plan->target().device != device || plan->target().cpu_kernels != cpu_kernels) {
    plan = std::make_shared<const Plan>(*this, PlanTarget{products_, device, training, cpu_kernels},
                                        profile_);
  }
  return *plan;
}

const Plan& TransHumanImpl::plan_of(const FrameCache& cache) {
  return plan(cache.training, cache.geometry.K.device());
}

FrameCache TransHumanImpl::prepare(const FrameInputs& in, double cull_distance) {
  in.check();
  FrameCache cache;
  cache.training = torch::GradMode::is_enabled();
  const auto opts = in.ref_images.options();
  const Plan& plan = this->plan(cache.training, opts.device());
  auto& geo = cache.geometry;
  geo.K = in.K.to(opts);
  geo.R = in.R.to(opts);
  geo.T = in.T.to(opts).reshape({-1, 3, 1});
  geo.Rh = in.Rh.to(opts);
  geo.Th = in.Th.to(opts).reshape({3});
  if (cull_distance > 0)
    geo.body = std::make_shared<render::BodyDistance>(in.vertices, cull_distance);

  const auto enc = plan.encode(in.ref_images);  // the encoder (METHOD 3.1)
  cache.network = plan.weights();               // the layers' weights, folded (9)
  if (human) {
    // Painting, then the human representation: TransHE tokens and DPaRF frames, or SPC (3.1-3.3).
    PaintedBody body;
    const auto vertices = in.vertices.to(opts);
    const auto uv = geometry::project_views(vertices, geo.K, geo.R, geo.T);
    body.features = plan.paint(enc, uv, in.visibility);
    body.xs_vertices = torch::mm(vertices - geo.Th, geo.Rh);
    cache.human = plan.represent(in, body);
  }
  // What per-point sampling reads of the encoder output (FDI's appearance branch, the colour head).
  cache.pixels = plan.pixels(enc, geo, in.vertices, cull_distance, cache.network);
  return cache;
}

TransHumanImpl::Trunk TransHumanImpl::trunk(const Plan& plan, const FrameCache& cache,
                                            const torch::Tensor& pts) {
  TORCH_CHECK(pts.dim() == 2 && pts.size(1) == 3, "pts must be (N, 3), got ", pts.sizes());
  const auto& geo = cache.geometry;
  torch::Tensor s;  // s_v, the human representation at the points (METHOD 3.3)
  if (human) s = plan.human(cache, torch::mm(pts - geo.Th, geo.Rh));
  // The points' projections into the reference views, and a_v (METHOD 3.4).
  const auto uv = geometry::project_views(pts, geo.K, geo.R, geo.T).permute({1, 0, 2}).contiguous();
  auto a = plan.appearance(cache, uv);
  if (a.defined()) a.relu_();
  return {plan.fuse(cache, s, a), uv};  // e_v = FDI(s_v, a_v)
}

torch::Tensor TransHumanImpl::color(const Plan& plan, const FrameCache& cache, const Trunk& t,
                                    const torch::Tensor& dirs) {
  const auto pixels = plan.colour_pixels(cache, t.uv);  // p_v, or its folded readout
  const auto code = direction_encoding(dirs / dirs.norm(2, 1, true));
  return plan.colour(cache, t.e, pixels, code);
}

torch::Tensor TransHumanImpl::forward(const FrameCache& cache, const torch::Tensor& pts,
                                      const torch::Tensor& dirs) {
  const Plan& plan = plan_of(cache);
  const auto t = trunk(plan, cache, pts);
  const auto sigma = plan.density(t.e);
  const auto rgb = color(plan, cache, t, dirs);
  return torch::cat({rgb, sigma.unsqueeze(1)}, 1);
}

torch::Tensor TransHumanImpl::density(const FrameCache& cache, const torch::Tensor& pts) {
  const Plan& plan = plan_of(cache);
  return plan.density(trunk(plan, cache, pts).e);
}

TransHumanImpl::DirectionalRaw TransHumanImpl::forward_directions(const FrameCache& cache,
                                                                  const torch::Tensor& pts,
                                                                  const torch::Tensor& directions) {
  TORCH_CHECK(directions.dim() == 2 && directions.size(1) == 3,
              "forward_directions: directions must be (K, 3), got ", directions.sizes());
  const Plan& plan = plan_of(cache);
  const auto t = trunk(plan, cache, pts);
  DirectionalRaw out;
  out.sigma = plan.density(t.e);
  const auto pixels = plan.colour_pixels(cache, t.uv);
  std::vector<torch::Tensor> rgb;
  const auto unit = directions.to(pts.options()) / directions.to(pts.options()).norm(2, 1, true);
  for (int64_t k = 0; k < unit.size(0); ++k) {
    const auto code = direction_encoding(unit[k].unsqueeze(0).expand({pts.size(0), 3}));
    rgb.push_back(plan.colour(cache, t.e, pixels, code));
  }
  out.rgb = torch::stack(rgb);
  return out;
}

torch::Tensor TransHumanImpl::forward_density_first(const FrameCache& cache,
                                                    const torch::Tensor& pts,
                                                    const torch::Tensor& dirs) {
  const Plan& plan = plan_of(cache);
  const auto t = trunk(plan, cache, pts);
  const auto sigma = plan.density(t.e);
  const auto idx = (sigma > 0).nonzero().flatten();
  // Every point has density (a translucent model): colour for all rows, without copying the
  // trunk's (N, V, 256) output row by row.
  if (idx.size(0) == pts.size(0))
    return torch::cat({color(plan, cache, t, dirs), sigma.unsqueeze(1)}, 1);
  auto raw = torch::zeros({pts.size(0), 4}, sigma.options());
  raw.select(1, 3).copy_(sigma);
  if (idx.size(0) == 0) return raw;
  const Trunk sub{t.e.index_select(0, idx), t.uv.index_select(0, idx)};
  raw.index_copy_(0, idx,
                  torch::cat({color(plan, cache, sub, dirs.index_select(0, idx)),
                              sigma.index_select(0, idx).unsqueeze(1)},
                             1));
  return raw;
}

// ---- chunked evaluation with recomputation in the backward pass ------------------------------

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

std::vector<ParameterCount> parameter_counts(const TransHumanImpl& model) {
  std::vector<ParameterCount> out{{"encoder (ResNet-18 to layer2)", 0}, {"reduction + colour", 0}};
  const bool spc = model.config().representation == Representation::spc_trilinear;
  if (model.human) out.push_back({spc ? "SPC network" : "ViT", 0});
  out.push_back({"heads (fc_0, FDI, density, colour)", 0});
  auto find = [&](const std::string& name) -> int64_t& {
    for (auto& c : out)
      if (c.module == name) return c.count;
    throw std::logic_error("no parameter group " + name);
  };
  for (const auto& p : model.named_parameters()) {
    const auto& k = p.key();
    auto starts = [&](const char* prefix) { return k.rfind(prefix, 0) == 0; };
    int64_t* slot;
    if (starts("encoder.model."))
      slot = &find("encoder (ResNet-18 to layer2)");
    else if (starts("encoder."))
      slot = &find("reduction + colour");
    else if (starts("human.ViT."))
      slot = &find("ViT");
    else if (starts("human.embed.") || starts("human.conv."))
      slot = &find("SPC network");
    else
      slot = &find("heads (fc_0, FDI, density, colour)");
    *slot += p.value().numel();
  }
  int64_t total = 0;
  for (const auto& c : out) total += c.count;
  out.push_back({"total", total});
  return out;
}

}  // namespace th::model
