#pragma once
// LPIPS v0.1 with VGG16 features (METHOD 5, 6): the perceptual training loss and the evaluation
// metric. Weights come from a file the user converts once with scripts/export_lpips.py
// (torchvision's VGG16 ImageNet weights + LPIPS v0.1 linear layers), an .npz with the keys
//   features.{0,2,5,7,10,12,14,17,19,21,24,26,28}.{weight,bias}   VGG16 convolutions
//   lin{0..4}.weight                                            (1, C, 1, 1) linear layers
// Without the file LPIPS is unavailable: callers report it as such, never a made-up number.

#include <torch/nn/module.h>
#include <torch/nn/modules/container/sequential.h>
#include <torch/types.h>

#include <filesystem>
#include <memory>
#include <vector>

namespace th::metrics {

class LpipsImpl : public torch::nn::Module {
 public:
  LpipsImpl();
  // Loads the weights; throws th::Error naming the file and a missing or mis-shaped key.
  void load(const std::filesystem::path& file);

  // a, b: (B, 3, H, W) already in [-1, 1]. Returns (B) distances. Differentiable in a and b;
  // the network's own weights are frozen.
  torch::Tensor forward(const torch::Tensor& a, const torch::Tensor& b);

 private:
  std::vector<torch::nn::Sequential> slices_;  // VGG16 up to relu1_2, relu2_2, ..., relu5_3
  std::vector<torch::Tensor> lin_;             // (1, C, 1, 1)
  torch::Tensor shift_, scale_;
};
TORCH_MODULE(Lpips);

// Loads LPIPS from `file` (on `device`, eval mode, frozen), or returns nullptr with a warning
// naming what is off when the path is empty or missing (`purpose`: "the perceptual loss",
// "the LPIPS metric").
std::shared_ptr<LpipsImpl> try_load_lpips(const std::string& file, const torch::Device& device,
                                          const std::string& purpose);

}  // namespace th::metrics
