#include "model/kernels/onednn_linear.hpp"

#include <torch/csrc/autograd/custom_function.h>
#include <torch/torch.h>

#include <stdexcept>
#include <string>
#include <unordered_map>

#ifdef TH_ONEDNN_DIRECT
#include <oneapi/dnnl/dnnl.hpp>
#endif

#include "model/kernels/forms.hpp"

namespace th::model::kernels {
namespace {

#ifdef TH_ONEDNN_DIRECT

// oneDNN's inner-product primitive run on the tensors' own memory: x and y in their plain
// row-major layout, the weights reordered to the layout the primitive asks for. In fp32 the
// primitive, its descriptors and the weights' layout are those LibTorch's mkldnn_linear builds,
// so the products are the same to the bit (tests/model/test_precision.cpp); what it saves is the
// copy of x into a oneDNN tensor and of the result out of one. In bf16 (x and w bf16, b fp32) the
// same primitive takes bf16 operands, accumulates in fp32, adds the fp32 bias and rounds y to bf16
// once.
torch::Tensor onednn_product(const torch::Tensor& x2, const torch::Tensor& w,
                             const torch::Tensor& b) {
  const auto x = x2.contiguous();
  const auto wc = w.contiguous();
  const int64_t M = x.size(0), K = x.size(1), N = wc.size(0);
  auto y = torch::empty({M, N}, x.options());
  if (M == 0 || N == 0) return y;
  if (K == 0) return b.defined() ? y.copy_(b.expand({M, N})) : y.zero_();
  using tag = dnnl::memory::format_tag;
  using desc = dnnl::memory::desc;
  const auto f32 = dnnl::memory::data_type::f32;
  const auto type = x.scalar_type() == torch::kBFloat16 ? dnnl::memory::data_type::bf16 : f32;
  static const dnnl::engine engine(dnnl::engine::kind::cpu, 0);
  thread_local dnnl::stream stream(engine);
  try {
    const desc src({M, K}, type, tag::ab), dst({M, N}, type, tag::ab);
    const desc plain_weights({N, K}, type, tag::ab), any_weights({N, K}, type, tag::any);
    const desc bias({N}, f32, tag::a);
    const auto prop = dnnl::prop_kind::forward_training;
    using ip = dnnl::inner_product_forward;
    const ip::primitive_desc pd(b.defined() ? ip::desc(prop, src, any_weights, bias, dst)
                                            : ip::desc(prop, src, any_weights, dst),
                                engine);
    dnnl::memory weights(plain_weights, engine, wc.data_ptr());
    if (pd.weights_desc() != plain_weights) {
      dnnl::memory packed(pd.weights_desc(), engine);
      dnnl::reorder(weights, packed).execute(stream, weights, packed);
      weights = packed;
    }
    std::unordered_map<int, dnnl::memory> args{
        {DNNL_ARG_SRC, dnnl::memory(src, engine, x.data_ptr())},
        {DNNL_ARG_WEIGHTS, weights},
        {DNNL_ARG_DST, dnnl::memory(dst, engine, y.data_ptr())}};
    torch::Tensor bc;
    if (b.defined()) {
      bc = b.to(torch::kFloat).contiguous();
      args.emplace(DNNL_ARG_BIAS, dnnl::memory(bias, engine, bc.data_ptr()));
    }
    ip(pd).execute(stream, args);
    stream.wait();
  } catch (const dnnl::error& e) {
    throw std::runtime_error("oneDNN inner product of (" + std::to_string(M) + ", " +
                             std::to_string(K) + ") by (" + std::to_string(N) + ", " +
                             std::to_string(K) + ")^T failed: " + e.what());
  }
  return y;
}

#else

// LibTorch's oneDNN product: x copied into a oneDNN tensor, the result copied out.
torch::Tensor onednn_product(const torch::Tensor& x2, const torch::Tensor& w,
                             const torch::Tensor& b) {
  const c10::optional<torch::Tensor> bias =
      b.defined() ? c10::optional<torch::Tensor>(b) : c10::nullopt;
  return at::mkldnn_linear(x2.contiguous().to_mkldnn(), w.contiguous(), bias).to_dense();
}

#endif

// No bias: an empty tensor (a custom function's inputs must be defined tensors).
struct OneDnnLinear : torch::autograd::Function<OneDnnLinear> {
  static torch::Tensor forward(torch::autograd::AutogradContext* ctx, const torch::Tensor& x2,
                               const torch::Tensor& w, const torch::Tensor& b) {
    ctx->save_for_backward({x2, w});
    const bool bias = b.numel() > 0;
    ctx->saved_data["bias"] = bias;
    return onednn_product(x2, w, bias ? b : torch::Tensor());
  }
  static torch::autograd::variable_list backward(torch::autograd::AutogradContext* ctx,
                                                 torch::autograd::variable_list grads) {
    const auto saved = ctx->get_saved_variables();
    const auto &x2 = saved[0], &w = saved[1];
    const auto g = grads[0].contiguous();
    torch::Tensor gx, gw, gb;
    if (ctx->needs_input_grad(0)) gx = onednn_product(g, w.t().contiguous(), {});
    if (ctx->needs_input_grad(1)) gw = torch::mm(g.t(), x2);
    if (ctx->saved_data["bias"].toBool() && ctx->needs_input_grad(2))
      gb = g.sum(0, false, torch::kFloat);
    return {gx, gw, gb};
  }
};

}  // namespace

bool onednn_bf16() { return onednn_direct(); }

bool onednn_direct() {
#ifdef TH_ONEDNN_DIRECT
  return true;
#else
  return false;
#endif
}

torch::Tensor onednn_linear(const torch::Tensor& x2, const torch::Tensor& w,
                            const torch::Tensor& b) {
  TORCH_CHECK(x2.scalar_type() == w.scalar_type() &&
                  (x2.scalar_type() == torch::kFloat ||
                   (x2.scalar_type() == torch::kBFloat16 && onednn_bf16())),
              "oneDNN product: x and w must be fp32 (or bf16 where onednn_bf16()), got ",
              x2.scalar_type(), " and ", w.scalar_type());
  if (!cpu_kernels(x2.device()) || x2.size(0) == 0) return torch::nn::functional::linear(x2, w, b);
  const bool grad = torch::GradMode::is_enabled() &&
                    (x2.requires_grad() || w.requires_grad() || (b.defined() && b.requires_grad()));
  if (!grad) return onednn_product(x2, w, b);
  return OneDnnLinear::apply(x2, w, b.defined() ? b : torch::empty({0}, w.options()));
}

}  // namespace th::model::kernels
