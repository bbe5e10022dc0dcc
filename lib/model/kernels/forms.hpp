#pragma once
// Which form of a kernel family runs. Each family has a CPU kernel (one pass over the points,
// with its own backward where it has one) and a LibTorch form: the same arithmetic in
// device-agnostic LibTorch operations, differentiated by autograd, which is what runs on a GPU.
// Tensors on the CPU take the CPU kernel, others the LibTorch form. While a LibTorchForms object
// lives, the CPU takes the LibTorch forms too, on the thread that made it: the arithmetic a GPU
// runs, testable on a CPU (tests/model/test_network.cpp).

#include <c10/core/Device.h>

namespace th::model::kernels {

// True where the CPU kernels run: a CPU device, outside any LibTorchForms on this thread.
bool cpu_kernels(const c10::Device& device);

class LibTorchForms {
 public:
  LibTorchForms();
  ~LibTorchForms();
  LibTorchForms(const LibTorchForms&) = delete;
  LibTorchForms& operator=(const LibTorchForms&) = delete;

 private:
  bool previous_;
};

}  // namespace th::model::kernels
