#include "metrics/lpips.hpp"

#include <spdlog/spdlog.h>
#include <torch/torch.h>

#include "core/error.hpp"
#include "io/npy.hpp"

namespace th::metrics {
namespace nn = torch::nn;

namespace {

// torchvision's vgg16().features, as (index, in, out) of each conv; 'M' = max pool. The five
// LPIPS slices end after the ReLUs at features indices 3, 8, 15, 22, 29.
struct Conv {
  int index, in, out;
};
const std::vector<std::vector<Conv>> kSlices = {{{0, 3, 64}, {2, 64, 64}},
                                                {{5, 64, 128}, {7, 128, 128}},
                                                {{10, 128, 256}, {12, 256, 256}, {14, 256, 256}},
                                                {{17, 256, 512}, {19, 512, 512}, {21, 512, 512}},
                                                {{24, 512, 512}, {26, 512, 512}, {28, 512, 512}}};

}  // namespace

LpipsImpl::LpipsImpl() {
  for (size_t s = 0; s < kSlices.size(); ++s) {
    nn::Sequential seq;
    if (s > 0) seq->push_back(nn::MaxPool2d(nn::MaxPool2dOptions(2).stride(2)));
    for (const auto& c : kSlices[s]) {
      seq->push_back(nn::Conv2d(nn::Conv2dOptions(c.in, c.out, 3).padding(1)));
      seq->push_back(nn::ReLU());
    }
    slices_.push_back(register_module("slice" + std::to_string(s), seq));
    lin_.push_back(
        register_buffer("lin" + std::to_string(s), torch::zeros({1, kSlices[s].back().out, 1, 1})));
  }
  shift_ = register_buffer("shift", torch::tensor({-.030f, -.088f, -.188f}).reshape({1, 3, 1, 1}));
  scale_ = register_buffer("scale", torch::tensor({.458f, .448f, .450f}).reshape({1, 3, 1, 1}));
}

void LpipsImpl::load(const std::filesystem::path& file) {
  if (!std::filesystem::exists(file)) fail("LPIPS weights '", file.string(), "' do not exist");
  const auto arrays = io::read_npz(file);
  auto take = [&](const std::string& key, const torch::Tensor& into) {
    auto it = arrays.find(key);
    if (it == arrays.end()) fail("LPIPS weights '", file.string(), "' have no '", key, "'");
    if (it->second.sizes() != into.sizes())
      fail("LPIPS weights '", file.string(), "': '", key, "' has shape ", it->second.sizes(),
           ", expected ", into.sizes());
    torch::NoGradGuard g;
    into.copy_(it->second.to(into.dtype()));
  };
  for (size_t s = 0; s < kSlices.size(); ++s) {
    size_t conv = 0;
    for (const auto& m : slices_[s]->children()) {
      auto* c = m->as<nn::Conv2d>();
      if (!c) continue;
      const std::string key = "features." + std::to_string(kSlices[s][conv++].index);
      take(key + ".weight", c->weight);
      take(key + ".bias", c->bias);
    }
    take("lin" + std::to_string(s) + ".weight", lin_[s]);
  }
  for (auto& p : parameters()) p.set_requires_grad(false);
}

torch::Tensor LpipsImpl::forward(const torch::Tensor& a, const torch::Tensor& b) {
  TORCH_CHECK(a.dim() == 4 && a.size(1) == 3 && a.sizes() == b.sizes(),
              "LPIPS inputs must be two (B, 3, H, W) tensors of one shape");
  auto x = (a - shift_) / scale_, y = (b - shift_) / scale_;
  auto unit = [](const torch::Tensor& f) {  // METHOD 5: x / (sqrt(sum x^2 + 1e-10) + 1e-10)
    return f / ((f.pow(2).sum(1, true) + 1e-10).sqrt() + 1e-10);
  };
  torch::Tensor total;
  for (size_t s = 0; s < slices_.size(); ++s) {
    x = slices_[s]->forward(x);
    y = slices_[s]->forward(y);
    const auto d = (unit(x) - unit(y)).pow(2);
    const auto layer = torch::conv2d(d, lin_[s]).mean({1, 2, 3});
    total = total.defined() ? total + layer : layer;
  }
  return total;
}

std::shared_ptr<LpipsImpl> try_load_lpips(const std::string& file, const torch::Device& device,
                                          const std::string& purpose) {
  if (file.empty()) {
    spdlog::warn(
        "no LPIPS weights configured: {} is off (make the file once with "
        "scripts/export_lpips.py)",
        purpose);
    return nullptr;
  }
  if (!std::filesystem::exists(file)) {
    spdlog::warn("LPIPS weights '{}' not found: {} is off", file, purpose);
    return nullptr;
  }
  auto lpips = std::make_shared<LpipsImpl>();
  lpips->load(file);
  lpips->to(device);
  lpips->eval();
  return lpips;
}

}  // namespace th::metrics
