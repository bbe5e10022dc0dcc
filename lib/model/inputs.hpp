#pragma once
// What the network consumes for one frame: plain tensors, produced by the data pipeline.
// Sizes come from the tensors (the synthetic body has fewer vertices than SMPL's 6890).

#include <torch/types.h>

#include <cstdint>
#include <string>

namespace th::model {

struct FrameInputs {
  torch::Tensor ref_images;  // (V, 3, H, W) float in [0, 1], background black (METHOD 2.1)
  torch::Tensor K;           // (V, 3, 3) intrinsics at the working resolution
  torch::Tensor R;           // (V, 3, 3) world -> camera rotation
  torch::Tensor T;           // (V, 3, 1) world -> camera translation, metres
  torch::Tensor vertices;    // (Nv, 3) posed body vertices, world coordinates
  torch::Tensor Rh;          // (3, 3) global rotation matrix: x_smpl = Rh^T (x_world - Th)
  torch::Tensor Th;          // (3) global translation, metres
  torch::Tensor A;           // (Nv, 3, 3) blended canonical -> posed rotations (METHOD 2.3)
  torch::Tensor canonical;   // (Nv, 3) canonical vertices (v_template); float64 keeps the token
                            // positions, hence the high PE frequencies, as the reference's [parity]
  torch::Tensor visibility;  // (V, Nv) bool, vertex visible in reference view v (METHOD 2.4)
  torch::Tensor labels;      // (Nv) int64 token (cluster) of each vertex (METHOD 2.5)
  int64_t num_tokens = 0;    // number of clusters; 0: labels.max() + 1

  int64_t views() const { return ref_images.size(0); }
  int64_t num_vertices() const { return vertices.size(0); }
  // Checks shapes and dtypes; TORCH_CHECK names the offending tensor.
  void check() const;
};

// The token groups a model's weights were trained with (METHOD 2.5): which token each body
// vertex belongs to. They are part of the model like its weights: every checkpoint stores them,
// and a loaded model renders with the stored labels, never with labels computed anew.
struct TokenGroups {
  torch::Tensor labels;  // (Nv) int64 on the CPU; undefined for a grouping made per frame
  std::string origin;    // what made them, e.g. "canonical_kmeans num_tokens=300 seed=42"

  bool empty() const { return origin.empty(); }
};

// Whether two frames' inputs are the same values (dtypes, shapes and every element): a frame
// prepared for one is the frame of the other.
bool same_inputs(const FrameInputs& a, const FrameInputs& b);

}  // namespace th::model
