#pragma once
// Body grouping (METHOD 2.5): which token each body vertex belongs to. The paper's choice is
// k-means on the canonical vertices (computed once, cached); the ablations voxelise canonical
// space or the posed body of each frame on a grid instead.

#include <torch/types.h>

#include <filesystem>
#include <memory>
#include <string>

#include "core/config.hpp"

namespace th::body {

// Deterministic k-means (k-means++ seeding from `seed`, Lloyd iterations to convergence; an
// empty cluster is re-seeded with the point farthest from its centre).
// points: (N, 3); returns labels (N) int64 in [0, k), every cluster non-empty.
torch::Tensor kmeans(const torch::Tensor& points, int k, int64_t seed, int max_iterations = 300);

// k-means labels cached in cache_dir as kmeans_<hash of points>_k<k>_s<seed>.npy.
torch::Tensor kmeans_cached(const torch::Tensor& points, int k, int64_t seed,
                            const std::filesystem::path& cache_dir);

// The reference implementation's kmeans_dict_300.npy (pickled dict, `pc2voxel_ind` labels),
// compacted to [0, clusters). num_vertices < 0: the count is checked by the caller.
torch::Tensor load_reference_kmeans(const std::filesystem::path& file, int64_t num_vertices);

// Whether the config names a reference label file (kmeans_file set, and not "compute").
bool uses_reference_kmeans(const GroupingConfig& config);

// What makes a config's token groups, in words stored with a checkpoint's labels:
// "canonical_kmeans num_tokens=300 seed=42", "reference file <path>", ...
std::string describe(const GroupingConfig& config);

// Fails, naming `source`, unless `labels` are token groups: (N) int64, N > 0, values in
// [0, tokens) with every token holding at least one vertex.
void check_labels(const torch::Tensor& labels, const std::string& source);

// Grid voxelisation: labels of the non-empty cells of a cubic grid whose cell size is chosen
// so that about `target_cells` cells are occupied (bisection on the cell size); labels are
// compacted to [0, cells). points: (N, 3) -> (N) int64.
torch::Tensor grid_labels(const torch::Tensor& points, int target_cells);

// The grouping a model config asks for.
class Grouping {
 public:
  virtual ~Grouping() = default;
  // canonical: (N, 3) v_template; posed_smpl: (N, 3) the frame's vertices in the SMPL frame.
  // Returns (N) int64 labels in [0, number of tokens).
  virtual torch::Tensor labels(const torch::Tensor& canonical, const torch::Tensor& posed_smpl) = 0;
  // True when labels do not depend on the frame (computed once).
  virtual bool is_static() const = 0;
};

std::unique_ptr<Grouping> make_grouping(const GroupingConfig& config);

// Cluster sizes of a labelling: (tokens) int64.
torch::Tensor cluster_sizes(const torch::Tensor& labels);

}  // namespace th::body
