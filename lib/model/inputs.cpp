#include "model/inputs.hpp"

#include <torch/torch.h>

namespace th::model {

void FrameInputs::check() const {
  TORCH_CHECK(ref_images.defined() && ref_images.dim() == 4 && ref_images.size(1) == 3,
              "FrameInputs.ref_images must be (V, 3, H, W), got ",
              ref_images.defined() ? ref_images.sizes() : c10::IntArrayRef{});
  const auto V = ref_images.size(0);
  TORCH_CHECK(K.defined() && K.sizes() == torch::IntArrayRef({V, 3, 3}), "FrameInputs.K must be (",
              V, ", 3, 3)");
  TORCH_CHECK(R.defined() && R.sizes() == torch::IntArrayRef({V, 3, 3}), "FrameInputs.R must be (",
              V, ", 3, 3)");
  TORCH_CHECK(T.defined() && T.numel() == V * 3, "FrameInputs.T must be (", V, ", 3, 1)");
  TORCH_CHECK(vertices.defined() && vertices.dim() == 2 && vertices.size(1) == 3,
              "FrameInputs.vertices must be (Nv, 3)");
  const auto nv = vertices.size(0);
  TORCH_CHECK(Rh.defined() && Rh.sizes() == torch::IntArrayRef({3, 3}),
              "FrameInputs.Rh must be (3, 3)");
  TORCH_CHECK(Th.defined() && Th.numel() == 3, "FrameInputs.Th must have 3 elements");
  TORCH_CHECK(A.defined() && A.sizes() == torch::IntArrayRef({nv, 3, 3}), "FrameInputs.A must be (",
              nv, ", 3, 3), got ", A.defined() ? A.sizes() : c10::IntArrayRef{});
  TORCH_CHECK(canonical.defined() && canonical.sizes() == vertices.sizes(),
              "FrameInputs.canonical must be (", nv, ", 3)");
  TORCH_CHECK(visibility.defined() && visibility.sizes() == torch::IntArrayRef({V, nv}),
              "FrameInputs.visibility must be (", V, ", ", nv, ")");
  TORCH_CHECK(labels.defined() && labels.dim() == 1 && labels.size(0) == nv &&
                  labels.scalar_type() == torch::kLong,
              "FrameInputs.labels must be (", nv, ") int64");
}

bool same_inputs(const FrameInputs& a, const FrameInputs& b) {
  auto same = [](const torch::Tensor& x, const torch::Tensor& y) {
    if (x.defined() != y.defined()) return false;
    if (!x.defined()) return true;
    return x.scalar_type() == y.scalar_type() && x.device() == y.device() &&
           x.sizes() == y.sizes() && torch::equal(x, y);
  };
  return a.num_tokens == b.num_tokens && same(a.ref_images, b.ref_images) && same(a.K, b.K) &&
         same(a.R, b.R) && same(a.T, b.T) && same(a.vertices, b.vertices) && same(a.Rh, b.Rh) &&
         same(a.Th, b.Th) && same(a.A, b.A) && same(a.canonical, b.canonical) &&
         same(a.visibility, b.visibility) && same(a.labels, b.labels);
}

}  // namespace th::model
