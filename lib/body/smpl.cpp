#include "body/smpl.hpp"

#include <torch/torch.h>

#include <fstream>
#include <functional>
#include <sstream>

#include "core/error.hpp"
#include "core/files.hpp"
#include "geometry/camera.hpp"
#include "io/npy.hpp"
#include "io/pickle.hpp"

namespace th::body {
namespace fs = std::filesystem;

const std::array<const char*, kNumJoints> kJointNames = {
    "pelvis",     "left_hip",    "right_hip",    "spine1",      "left_knee",     "right_knee",
    "spine2",     "left_ankle",  "right_ankle",  "spine3",      "left_foot",     "right_foot",
    "neck",       "left_collar", "right_collar", "head",        "left_shoulder", "right_shoulder",
    "left_elbow", "right_elbow", "left_wrist",   "right_wrist", "left_hand",     "right_hand"};

const std::array<int, kNumJoints> kParents = {-1, 0, 0, 0,  1,  2,  3,  4,  5,  6,  7,  8,
                                              9,  9, 9, 12, 13, 14, 16, 17, 18, 19, 20, 21};

std::vector<int> SmplModel::parents() const {
  auto row = kintree_table[0].to(torch::kInt64).contiguous();
  std::vector<int> p(row.numel());
  for (int64_t j = 0; j < row.numel(); ++j) p[j] = static_cast<int>(row[j].item<int64_t>());
  // SMPL stores the root's parent as uint32 -1 (4294967295) or int -1.
  if (!p.empty()) p[0] = -1;
  return p;
}

void SmplModel::validate(const std::string& source) const {
  auto bad = [&](const std::string& field, const std::string& what) {
    fail("SMPL model '", source, "': field '", field, "' ", what);
  };
  if (v_template.dim() != 2 || v_template.size(1) != 3) bad("v_template", "must be (V, 3)");
  const int64_t V = v_template.size(0);
  auto shape_str = [](const torch::Tensor& t) {
    std::ostringstream s;
    s << t.sizes();
    return s.str();
  };
  if (shapedirs.dim() != 3 || shapedirs.size(0) != V || shapedirs.size(1) != 3)
    bad("shapedirs", "must be (V, 3, S), got " + shape_str(shapedirs));
  if (posedirs.dim() != 3 || posedirs.size(0) != V || posedirs.size(1) != 3 ||
      posedirs.size(2) != kNumPoseBlend)
    bad("posedirs", "must be (V, 3, 207), got " + shape_str(posedirs));
  if (J_regressor.dim() != 2 || J_regressor.size(0) != kNumJoints || J_regressor.size(1) != V)
    bad("J_regressor", "must be (24, V), got " + shape_str(J_regressor));
  if (weights.dim() != 2 || weights.size(0) != V || weights.size(1) != kNumJoints)
    bad("weights", "must be (V, 24), got " + shape_str(weights));
  if (kintree_table.dim() != 2 || kintree_table.size(0) != 2 || kintree_table.size(1) != kNumJoints)
    bad("kintree_table", "must be (2, 24), got " + shape_str(kintree_table));
  if (faces.dim() != 2 || faces.size(1) != 3) bad("f", "must be (F, 3), got " + shape_str(faces));
  if (faces.numel() > 0 && (faces.min().item<int64_t>() < 0 || faces.max().item<int64_t>() >= V))
    bad("f", "indexes vertices outside [0, " + std::to_string(V) + ")");
  const auto p = parents();
  for (int j = 1; j < kNumJoints; ++j)
    if (p[j] < 0 || p[j] >= j) bad("kintree_table", "is not a tree ordered parents-first");
}

namespace {

SmplModel from_fields(const std::function<torch::Tensor(const char*)>& field,
                      const std::string& source) {
  SmplModel m;
  m.v_template = field("v_template").to(torch::kFloat64).contiguous();
  m.shapedirs = field("shapedirs").to(torch::kFloat64).contiguous();
  m.posedirs = field("posedirs").to(torch::kFloat64).contiguous();
  m.J_regressor = field("J_regressor").to(torch::kFloat64).contiguous();
  m.weights = field("weights").to(torch::kFloat64).contiguous();
  m.kintree_table = field("kintree_table").to(torch::kInt64).contiguous();
  m.faces = field("f").to(torch::kInt64).contiguous();
  m.validate(source);
  return m;
}

// Pickle opcodes (protocol 2) used to frame SMPL's dict.
constexpr char kProto2[] = "\x80\x02";
constexpr char kEmptyDict = '}', kMark = '(', kSetItems = 'u', kStop = '.', kNone = 'N',
               kTuple3 = '\x87', kReduce = 'R', kBuild = 'b', kBinUnicode = 'X', kGlobal = 'c';

// th::io's pickle of one value without its PROTO header and STOP, to be embedded in a larger
// pickle. Each embedded value numbers its memo from 0 again; pickle allows a later BINPUT to
// replace an entry, and every BINGET of a value refers to its own entries.
std::string embedded(const io::Value& v) {
  const std::string b = io::pickle_bytes(v, 2);
  TORCH_CHECK(b.size() > 3 && b.compare(0, 2, kProto2, 2) == 0 && b.back() == kStop,
              "unexpected pickle framing from th::io");
  return b.substr(2, b.size() - 3);
}

std::string binunicode(const std::string& s) {
  std::string out(1, kBinUnicode);
  for (int i = 0; i < 4; ++i) out.push_back(char((s.size() >> (8 * i)) & 0xff));
  return out + s;
}

// A dense (rows, cols) matrix as SMPL's files pickle J_regressor (Python 2, protocol 2):
// copy_reg._reconstructor(scipy.sparse.csc.csc_matrix, object, None), then BUILD with the
// state {'_shape', 'maxprint', 'data', 'indices', 'indptr'} (int32 indices). th::io::Value
// cannot express an object for writing, so the opcodes are written here.
std::string csc_pickle(const torch::Tensor& dense) {
  auto d = dense.to(torch::kFloat64).contiguous();
  const int64_t rows = d.size(0), cols = d.size(1);
  auto a = d.accessor<double, 2>();
  std::vector<double> data;
  std::vector<int32_t> indices, indptr{0};
  for (int64_t c = 0; c < cols; ++c) {
    for (int64_t r = 0; r < rows; ++r)
      if (a[r][c] != 0.0) {
        data.push_back(a[r][c]);
        indices.push_back(static_cast<int32_t>(r));
      }
    indptr.push_back(static_cast<int32_t>(data.size()));
  }
  auto vec = [](auto& v, torch::Dtype t) {
    return torch::from_blob(v.data(), {static_cast<int64_t>(v.size())}, t).clone();
  };
  io::Value::Dict state;
  state.emplace_back(io::Value::str("_shape"),
                     io::Value::tuple({io::Value::integer(rows), io::Value::integer(cols)}));
  state.emplace_back(io::Value::str("maxprint"), io::Value::integer(50));
  state.emplace_back(io::Value::str("data"), io::Value::array(vec(data, torch::kFloat64)));
  state.emplace_back(io::Value::str("indices"), io::Value::array(vec(indices, torch::kInt32)));
  state.emplace_back(io::Value::str("indptr"), io::Value::array(vec(indptr, torch::kInt32)));
  std::string out;
  out += kGlobal + std::string("copy_reg\n_reconstructor\n");
  out += kGlobal + std::string("scipy.sparse.csc\ncsc_matrix\n");
  out += kGlobal + std::string("__builtin__\nobject\n");
  out += kNone;
  out += kTuple3;
  out += kReduce;
  out += embedded(io::Value::dict(std::move(state)));
  out += kBuild;
  return out;
}

torch::Tensor as_row(const torch::Tensor& t, int64_t n, const char* name) {
  auto r = t.to(torch::kFloat64).reshape({-1});
  TORCH_CHECK(r.numel() == n, name, " must hold ", n, " values, got ", t.sizes());
  return r;
}

}  // namespace

SmplModel smpl_from_value(const io::Value& dict, const std::string& source) {
  return from_fields(
      [&](const char* key) {
        const io::Value* v = dict.find(key);
        if (!v) fail("SMPL model '", source, "': missing field '", key, "'");
        try {
          return v->as_tensor();
        } catch (const Error& e) {
          fail("SMPL model '", source, "': field '", key, "': ", e.what());
        }
      },
      source);
}

SmplModel load_smpl(const fs::path& path) {
  if (!fs::exists(path)) fail("SMPL model '", path.string(), "' does not exist");
  const std::string ext = path.extension().string();
  if (ext == ".npz") {
    const auto arrays = io::read_npz(path);
    return from_fields(
        [&](const char* key) {
          auto it = arrays.find(key);
          if (it == arrays.end())
            fail("SMPL model '", path.string(), "': missing field '", key, "'");
          return it->second;
        },
        path.string());
  }
  if (ext == ".pkl") return smpl_from_value(io::read_pickle(path), path.string());
  fail("SMPL model '", path.string(), "': unknown extension '", ext, "' (expected .pkl or .npz)");
}

void save_smpl_npz(const fs::path& path, const SmplModel& m) {
  io::write_npz(path, {{"v_template", m.v_template},
                       {"shapedirs", m.shapedirs},
                       {"posedirs", m.posedirs},
                       {"J_regressor", m.J_regressor},
                       {"weights", m.weights},
                       {"kintree_table", m.kintree_table},
                       {"f", m.faces}});
}

void save_smpl_pkl(const fs::path& path, const SmplModel& m) {
  using io::Value;
  std::string out = kProto2;
  out += kEmptyDict;
  out += kMark;
  auto put = [&](const char* key, const std::string& value_pickle) {
    out += binunicode(key) + value_pickle;
  };
  put("J_regressor", csc_pickle(m.J_regressor));
  put("f", embedded(Value::array(m.faces)));
  put("kintree_table", embedded(Value::array(m.kintree_table)));
  put("J", embedded(Value::array(torch::matmul(m.J_regressor, m.v_template))));
  put("weights", embedded(Value::array(m.weights)));
  put("posedirs", embedded(Value::array(m.posedirs)));
  put("bs_style", embedded(Value::str("lbs")));
  put("v_template", embedded(Value::array(m.v_template)));
  put("shapedirs", embedded(Value::array(m.shapedirs)));
  put("bs_type", embedded(Value::str("lrotmin")));
  out += kSetItems;
  out += kStop;
  write_file_atomic(path, out);
}

LbsResult lbs(const SmplModel& m, const torch::Tensor& poses, const torch::Tensor& shapes) {
  const auto opts = torch::TensorOptions().dtype(torch::kFloat64);
  auto pose = as_row(poses, kNumPoseParams, "lbs: poses");
  auto beta = shapes.to(torch::kFloat64).reshape({-1});
  TORCH_CHECK(beta.numel() <= m.num_betas(), "lbs: ", beta.numel(), " shape coefficients for a ",
              "model with ", m.num_betas());

  LbsResult r;
  // METHOD 2.3: v_shaped = v_template + shapedirs . shapes; J = J_regressor . v_shaped.
  r.v_shaped = m.v_template + torch::matmul(m.shapedirs.slice(2, 0, beta.numel()), beta);
  r.joints = torch::matmul(m.J_regressor, r.v_shaped);

  auto rot = geometry::rodrigues(pose.reshape({kNumJoints, 3}));  // (24, 3, 3)
  // SMPL's pose blend shapes (zero for the synthetic model): features R_j - I, j >= 1.
  auto pose_feature = (rot.slice(0, 1) - torch::eye(3, opts)).reshape({kNumPoseBlend});
  auto v_posed = r.v_shaped + torch::matmul(m.posedirs, pose_feature);

  const auto parent = m.parents();
  std::vector<torch::Tensor> G(kNumJoints);
  auto bottom = torch::tensor({0.0, 0.0, 0.0, 1.0}, opts).reshape({1, 4});
  for (int j = 0; j < kNumJoints; ++j) {
    auto t = parent[j] < 0 ? r.joints[j] : r.joints[j] - r.joints[parent[j]];
    auto local = torch::cat({torch::cat({rot[j], t.reshape({3, 1})}, 1), bottom}, 0);
    G[j] = parent[j] < 0 ? local : torch::matmul(G[parent[j]], local);
  }
  auto Gs = torch::stack(G);  // (24, 4, 4)
  r.posed_joints = Gs.slice(1, 0, 3).select(2, 3).clone();
  // Remove the rest offset: G_j[:3, 3] -= G_j[:3, :3] J_j.
  auto offset = torch::matmul(Gs.slice(1, 0, 3).slice(2, 0, 3), r.joints.unsqueeze(2));
  r.G = Gs.clone();
  r.G.slice(1, 0, 3).select(2, 3).sub_(offset.squeeze(2));
  r.A = torch::matmul(m.weights, r.G.reshape({kNumJoints, 16})).reshape({-1, 4, 4});
  r.vertices = torch::matmul(r.A.slice(1, 0, 3).slice(2, 0, 3), v_posed.unsqueeze(2)).squeeze(2) +
               r.A.slice(1, 0, 3).select(2, 3);
  return r;
}

torch::Tensor skin_points(const torch::Tensor& points, const torch::Tensor& weights,
                          const torch::Tensor& G) {
  TORCH_CHECK(points.dim() == 2 && points.size(1) == 3, "skin_points: points must be (P, 3), got ",
              points.sizes());
  TORCH_CHECK(
      weights.dim() == 2 && weights.size(0) == points.size(0) && weights.size(1) == G.size(0),
      "skin_points: weights must be (P, ", G.size(0), "), got ", weights.sizes());
  auto A =
      torch::matmul(weights.to(torch::kFloat64), G.reshape({G.size(0), 16})).reshape({-1, 4, 4});
  auto p = points.to(torch::kFloat64);
  return torch::matmul(A.slice(1, 0, 3).slice(2, 0, 3), p.unsqueeze(2)).squeeze(2) +
         A.slice(1, 0, 3).select(2, 3);
}

torch::Tensor smpl_to_world(const torch::Tensor& points, const torch::Tensor& Rh,
                            const torch::Tensor& Th) {
  auto R = geometry::rodrigues(as_row(Rh, 3, "Rh"));
  return torch::matmul(points.to(torch::kFloat64), R.transpose(0, 1)) +
         as_row(Th, 3, "Th").reshape({1, 3});
}

torch::Tensor world_to_smpl(const torch::Tensor& points, const torch::Tensor& Rh,
                            const torch::Tensor& Th) {
  // METHOD 2.2: x_smpl = Rh^T (x_world - Th); row vectors, so multiply by R on the right.
  auto R = geometry::rodrigues(as_row(Rh, 3, "Rh"));
  return torch::matmul(points.to(torch::kFloat64) - as_row(Th, 3, "Th").reshape({1, 3}), R);
}

}  // namespace th::body
