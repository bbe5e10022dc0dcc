// SMPL model I/O and LBS (lib/body/smpl): LBS against an independent numpy implementation
// (tests/python/lbs_reference.py, rotations from scipy), on a random model with non-zero pose
// blend shapes, through both file formats.

#include <torch/torch.h>

#include <catch2/catch.hpp>

#include "body/smpl.hpp"
#include "core/error.hpp"
#include "io/npy.hpp"
#include "support/test_env.hpp"

using namespace th::body;

namespace {

// A random SMPL-form model: V vertices, SMPL's kinematic tree, weights and J_regressor rows
// that sum to 1 (J_regressor sparse: 6 vertices per joint), non-zero posedirs.
SmplModel random_model(int64_t V, int64_t S, uint64_t seed) {
  torch::manual_seed(seed);
  const auto f64 = torch::kFloat64;
  SmplModel m;
  m.v_template = torch::randn({V, 3}, f64) * 0.3;
  m.shapedirs = torch::randn({V, 3, S}, f64) * 0.02;
  m.posedirs = torch::randn({V, 3, kNumPoseBlend}, f64) * 0.005;
  m.J_regressor = torch::zeros({kNumJoints, V}, f64);
  for (int j = 0; j < kNumJoints; ++j) {
    auto idx = torch::randperm(V, torch::kInt64).slice(0, 0, 6);
    auto w = torch::rand({6}, f64) + 0.1;
    m.J_regressor[j].index_put_({idx}, w / w.sum());
  }
  auto w = torch::rand({V, kNumJoints}, f64).pow(4);
  m.weights = w / w.sum(1, true);
  m.kintree_table = torch::zeros({2, kNumJoints}, torch::kInt64);
  for (int j = 0; j < kNumJoints; ++j) {
    m.kintree_table[0][j] = kParents[j];
    m.kintree_table[1][j] = j;
  }
  m.faces = torch::randint(0, V, {2 * V, 3}, torch::kInt64);
  return m;
}

}  // namespace

TEST_CASE("the joint tree and names are SMPL's", "[body]") {
  CHECK(std::string(kJointNames[0]) == "pelvis");
  CHECK(std::string(kJointNames[15]) == "head");
  CHECK(std::string(kJointNames[23]) == "right_hand");
  const std::array<int, 24> expected = {-1, 0, 0, 0,  1,  2,  3,  4,  5,  6,  7,  8,
                                        9,  9, 9, 12, 13, 14, 16, 17, 18, 19, 20, 21};
  CHECK(kParents == expected);
}

TEST_CASE("lbs at zero pose and shape rotates nothing and returns the template", "[body]") {
  auto m = random_model(60, 10, 1);
  auto r = lbs(m, torch::zeros({72}, torch::kFloat64), torch::zeros({10}, torch::kFloat64));
  auto eye = torch::eye(4, torch::kFloat64).expand({60, 4, 4});
  CHECK(torch::allclose(r.A, eye, 0, 1e-15));
  CHECK(torch::allclose(r.G, torch::eye(4, torch::kFloat64).expand({24, 4, 4}), 0, 1e-15));
  CHECK(torch::allclose(r.vertices, m.v_template, 0, 1e-15));
  CHECK(torch::allclose(r.joints, torch::matmul(m.J_regressor, m.v_template), 0, 1e-15));
  CHECK(torch::allclose(r.posed_joints, r.joints, 0, 1e-15));
}

TEST_CASE("lbs agrees with an independent numpy implementation to 1e-9 in float64", "[body]") {
  const auto dir = th::test::scratch_dir("body_lbs");
  auto m = random_model(80, 10, 2);
  torch::manual_seed(7);
  const int B = 6;
  auto poses = torch::randn({B, 72}, torch::kFloat64) * 0.6;
  poses[0].zero_();
  poses[1] *= 1e-7;  // tiny angles exercise the Taylor branch of Rodrigues
  auto shapes = torch::randn({B, 8}, torch::kFloat64) * 1.5;  // fewer than the model's 10
  th::io::write_npz(dir / "inputs.npz", {{"poses", poses}, {"shapes", shapes}});

  for (const char* format : {"npz", "pkl"}) {
    DYNAMIC_SECTION("model written as ." << format) {
      const auto model_path = dir / (std::string("model.") + format);
      if (std::string(format) == "npz")
        save_smpl_npz(model_path, m);
      else
        save_smpl_pkl(model_path, m);
      const auto out = dir / (std::string("reference_") + format + ".npz");
      REQUIRE(th::test::run_python("tests/python/lbs_reference.py",
                                   model_path.string() + " " + (dir / "inputs.npz").string() + " " +
                                       out.string()) == 0);
      auto ref = th::io::read_npz(out);
      const SmplModel loaded = load_smpl(model_path);
      for (int b = 0; b < B; ++b) {
        auto r = lbs(loaded, poses[b], shapes[b]);
        CHECK(torch::allclose(r.A, ref["A"][b], 0, 1e-9));
        CHECK(torch::allclose(r.G, ref["G"][b], 0, 1e-9));
        CHECK(torch::allclose(r.joints, ref["joints"][b], 0, 1e-9));
        CHECK(torch::allclose(r.posed_joints, ref["posed_joints"][b], 0, 1e-9));
        CHECK(torch::allclose(r.vertices, ref["vertices"][b], 0, 1e-9));
      }
    }
  }
}

TEST_CASE("the model reads back equal from .npz and .pkl", "[body]") {
  const auto dir = th::test::scratch_dir("body_io");
  auto m = random_model(40, 10, 3);
  save_smpl_npz(dir / "m.npz", m);
  save_smpl_pkl(dir / "m.pkl", m);
  for (const char* name : {"m.npz", "m.pkl"}) {
    const SmplModel r = load_smpl(dir / name);
    CHECK(torch::equal(r.v_template, m.v_template));
    CHECK(torch::equal(r.shapedirs, m.shapedirs));
    CHECK(torch::equal(r.posedirs, m.posedirs));
    CHECK(torch::equal(r.J_regressor, m.J_regressor));
    CHECK(torch::equal(r.weights, m.weights));
    CHECK(torch::equal(r.kintree_table, m.kintree_table));
    CHECK(torch::equal(r.faces, m.faces));
    CHECK(r.parents()[0] == -1);
  }
}

TEST_CASE("skin_points with the body's own weights reproduces lbs vertices", "[body]") {
  auto m = random_model(50, 10, 4);
  m.posedirs.zero_();  // skin_points applies no pose blend shapes
  torch::manual_seed(9);
  auto poses = torch::randn({72}, torch::kFloat64) * 0.5;
  auto shapes = torch::randn({10}, torch::kFloat64);
  auto r = lbs(m, poses, shapes);
  CHECK(torch::allclose(skin_points(r.v_shaped, m.weights, r.G), r.vertices, 0, 1e-12));
}

TEST_CASE("smpl_to_world and world_to_smpl are inverse (METHOD 2.2)", "[body]") {
  torch::manual_seed(11);
  auto pts = torch::randn({20, 3}, torch::kFloat64);
  auto Rh = torch::tensor({{0.3, -1.2, 0.4}}, torch::kFloat64);
  auto Th = torch::tensor({{0.1, 0.2, 0.9}}, torch::kFloat64);
  auto world = smpl_to_world(pts, Rh, Th);
  CHECK(torch::allclose(world_to_smpl(world, Rh, Th), pts, 0, 1e-12));
  // Translation alone shifts.
  auto shifted = smpl_to_world(pts, torch::zeros({3}, torch::kFloat64), Th);
  CHECK(torch::allclose(shifted - pts, Th.expand({20, 3}), 0, 1e-15));
}

TEST_CASE("load_smpl names the file and the field that is wrong", "[body]") {
  const auto dir = th::test::scratch_dir("body_errors");
  CHECK_THROWS_WITH(load_smpl(dir / "missing.npz"), Catch::Contains("missing.npz"));
  auto m = random_model(30, 10, 5);
  th::io::write_npz(dir / "partial.npz", {{"v_template", m.v_template}, {"f", m.faces}});
  CHECK_THROWS_WITH(load_smpl(dir / "partial.npz"), Catch::Contains("shapedirs"));
  th::io::write_npz(dir / "bad.npz", {{"v_template", m.v_template},
                                      {"shapedirs", m.shapedirs},
                                      {"posedirs", m.posedirs.slice(2, 0, 100)},
                                      {"J_regressor", m.J_regressor},
                                      {"weights", m.weights},
                                      {"kintree_table", m.kintree_table},
                                      {"f", m.faces}});
  CHECK_THROWS_AS(load_smpl(dir / "bad.npz"), th::Error);
  CHECK_THROWS_WITH(load_smpl(dir / "bad.npz"), Catch::Contains("posedirs"));
}
