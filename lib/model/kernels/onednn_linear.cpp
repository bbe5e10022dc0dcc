#include "model/kernels/onednn_linear.hpp"

#include <torch/csrc/autograd/custom_function.h>
#include <torch/torch.h>

#include "model/kernels/forms.hpp"

namespace th::model::kernels {
namespace {

torch::Tensor onednn_product(const torch::Tensor& x2, const torch::Tensor& w,
                             const torch::Tensor& b) {
  const c10::optional<torch::Tensor> bias =
      b.defined() ? c10::optional<torch::Tensor>(b) : c10::nullopt;
  return at::mkldnn_linear(x2.contiguous().to_mkldnn(), w.contiguous(), bias).to_dense();
}

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
    if (ctx->saved_data["bias"].toBool() && ctx->needs_input_grad(2)) gb = g.sum(0);
    return {gx, gw, gb};
  }
};

}  // namespace

torch::Tensor onednn_linear(const torch::Tensor& x2, const torch::Tensor& w,
                            const torch::Tensor& b) {
  if (!cpu_kernels(x2.device())) return torch::nn::functional::linear(x2, w, b);
  const bool grad = torch::GradMode::is_enabled() &&
                    (x2.requires_grad() || w.requires_grad() || (b.defined() && b.requires_grad()));
  if (!grad) return onednn_product(x2, w, b);
  return OneDnnLinear::apply(x2, w, b.defined() ? b : torch::empty({0}, w.options()));
}

}  // namespace th::model::kernels
