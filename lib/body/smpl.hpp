#pragma once
// The SMPL body model (METHOD 1.5) and linear blend skinning (METHOD 2.3).
//
// The model is read from SMPL's own pickled .pkl (chumpy arrays, sparse J_regressor) or from a
// plain .npz with the same field names (what transhuman-synth writes). All float fields are
// held as float64 on the CPU; LBS runs in float64 (METHOD 2.3).

#include <torch/types.h>

#include <array>
#include <filesystem>
#include <string>
#include <vector>

namespace th::io {
class Value;
}

namespace th::body {

constexpr int kNumJoints = 24;
constexpr int kNumPoseParams = 3 * kNumJoints;       // 72
constexpr int kNumPoseBlend = 9 * (kNumJoints - 1);  // 207

// SMPL's joint names in index order and its kinematic tree (parent of each joint; -1: root).
extern const std::array<const char*, kNumJoints> kJointNames;
extern const std::array<int, kNumJoints> kParents;

struct SmplModel {
  torch::Tensor v_template;     // (V, 3) float64, rest vertices (T-pose, y up, metres)
  torch::Tensor shapedirs;      // (V, 3, S) float64, shape blend directions
  torch::Tensor posedirs;       // (V, 3, 207) float64, pose blend directions
  torch::Tensor J_regressor;    // (24, V) float64, dense
  torch::Tensor weights;        // (V, 24) float64, skinning weights (rows sum to 1)
  torch::Tensor kintree_table;  // (2, 24) int64; row 0: parents (root: -1 or 2^32-1)
  torch::Tensor faces;          // (F, 3) int64 (field `f` on disk)

  int64_t num_vertices() const { return v_template.size(0); }
  int64_t num_betas() const { return shapedirs.size(2); }
  // Parents from kintree_table (root as -1).
  std::vector<int> parents() const;
  // Throws th::Error naming `source` if shapes or values are inconsistent.
  void validate(const std::string& source) const;
};

// Reads a model by extension: .pkl (SMPL's pickle) or .npz. Throws th::Error naming the file
// and the missing/malformed field.
SmplModel load_smpl(const std::filesystem::path& path);
// From an unpickled SMPL dict (sparse/chumpy fields already turned into tensors by th::io).
SmplModel smpl_from_value(const io::Value& dict, const std::string& source);

// Writes the model as np.savez would (fields v_template, shapedirs, posedirs, J_regressor
// (dense), weights, kintree_table, f). Atomic.
void save_smpl_npz(const std::filesystem::path& path, const SmplModel& model);
// Writes the model as a pickled dict with SMPL's field names (protocol 2), J_regressor as a
// scipy.sparse csc_matrix, plus `J` (rest joints), `bs_style` and `bs_type` as in SMPL's files.
void save_smpl_pkl(const std::filesystem::path& path, const SmplModel& model);

// Result of LBS for one pose and shape, all float64 in the SMPL frame (before Rh, Th).
struct LbsResult {
  torch::Tensor A;             // (V, 4, 4) per-vertex transforms (METHOD 2.3)
  torch::Tensor G;             // (24, 4, 4) joint transforms with the rest offset removed
  torch::Tensor joints;        // (24, 3) rest joints of the shaped body, J_regressor v_shaped
  torch::Tensor posed_joints;  // (24, 3) joints after posing
  torch::Tensor v_shaped;      // (V, 3) rest vertices with the shape applied
  torch::Tensor vertices;      // (V, 3) posed vertices (shape + pose blend shapes + skinning)
};

// poses: (72) or (1, 72) axis-angle per joint; shapes: (S') or (1, S'), S' <= S (missing
// coefficients are 0). METHOD 2.3.
LbsResult lbs(const SmplModel& model, const torch::Tensor& poses, const torch::Tensor& shapes);

// Skins arbitrary rest points with their own weights: points (P, 3) rest (shaped) positions,
// weights (P, 24), G (24, 4, 4) from lbs. Returns (P, 3) posed, SMPL frame.
torch::Tensor skin_points(const torch::Tensor& points, const torch::Tensor& weights,
                          const torch::Tensor& G);

// SMPL frame <-> world (METHOD 2.2): x_world = Rodrigues(Rh) x_smpl + Th.
// points: (N, 3); Rh, Th: (3), (1, 3) or (3, 1). Returns (N, 3) float64.
torch::Tensor smpl_to_world(const torch::Tensor& points, const torch::Tensor& Rh,
                            const torch::Tensor& Th);
torch::Tensor world_to_smpl(const torch::Tensor& points, const torch::Tensor& Rh,
                            const torch::Tensor& Th);

}  // namespace th::body
