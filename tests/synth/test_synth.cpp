// transhuman-synth (lib/synth): the body model, the generated dataset's structure and
// geometry (checked by numpy in tests/python/check_synth.py), determinism, and the rules for
// an existing output folder.

#include <torch/torch.h>

#include <catch2/catch.hpp>
#include <chrono>
#include <fstream>
#include <map>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <sstream>

#include "body/smpl.hpp"
#include "core/error.hpp"
#include "geometry/mesh.hpp"
#include "io/npy.hpp"
#include "support/bytes.hpp"
#include "support/test_env.hpp"
#include "synth/body_builder.hpp"
#include "synth/config.hpp"
#include "synth/generator.hpp"
#include "synth/layout.hpp"
#include "synth/png.hpp"
#include "synth/random.hpp"
#include "synth/rig.hpp"
#include "synth/split.hpp"

namespace fs = std::filesystem;
using namespace th::synth;

namespace {

SynthConfig tiny(std::vector<std::string> overrides = {}) {
  return th::config::load<SynthConfig>("configs/synth/tiny.yaml", overrides);
}

std::string read_all(const fs::path& p) {
  std::ifstream f(p, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(f), {});
}

// Relative path -> bytes of every file under dir.
std::map<std::string, std::string> snapshot(const fs::path& dir) {
  std::map<std::string, std::string> files;
  for (const auto& e : fs::recursive_directory_iterator(dir))
    if (e.is_regular_file()) files[fs::relative(e.path(), dir).string()] = read_all(e.path());
  return files;
}

// Per part: every edge is shared by exactly two faces of that part (a closed surface).
bool closed(const torch::Tensor& faces) {
  std::map<std::pair<int64_t, int64_t>, int> count;
  auto f = faces.contiguous();
  const int64_t* p = f.data_ptr<int64_t>();
  for (int64_t t = 0; t < f.size(0); ++t)
    for (int k = 0; k < 3; ++k) {
      int64_t a = p[3 * t + k], b = p[3 * t + (k + 1) % 3];
      ++count[{std::min(a, b), std::max(a, b)}];
    }
  for (const auto& [edge, n] : count)
    if (n != 2) return false;
  return true;
}

double height(const torch::Tensor& v) {
  return (v.select(1, 1).max() - v.select(1, 1).min()).item<double>();
}

}  // namespace

TEST_CASE("the body model has SMPL's form: tree and closed parts and weights and regressor",
          "[synth][body]") {
  const BodyTemplate bt = build_body_template();
  const auto& m = bt.model;
  const int64_t V = m.num_vertices();
  CHECK(V > 2000);
  CHECK(V < 8000);
  CHECK(m.shapedirs.sizes() == torch::IntArrayRef({V, 3, 10}));
  CHECK(m.posedirs.sizes() == torch::IntArrayRef({V, 3, 207}));
  CHECK(m.posedirs.abs().max().item<double>() == 0.0);
  CHECK(m.parents() == std::vector<int>(th::body::kParents.begin(), th::body::kParents.end()));
  CHECK(torch::allclose(m.weights.sum(1), torch::ones({V}, torch::kFloat64)));
  CHECK(torch::allclose(m.J_regressor.sum(1), torch::ones({24}, torch::kFloat64)));
  CHECK((m.J_regressor > 0).sum().item<int64_t>() < 24 * 64);  // sparse: rings of vertices
  // Smooth weights: joints blend near joints, e.g. some vertices share knee and hip.
  auto w = m.weights;
  CHECK(((w.select(1, 1) > 0.2) & (w.select(1, 4) > 0.2)).sum().item<int64_t>() > 0);
  CHECK(((w > 0.01).sum(1) >= 2).sum().item<int64_t>() > V / 10);
  // T-pose, y up, about 1.7 m; pelvis at the origin; arms along x.
  CHECK(height(m.v_template) > 1.65);
  CHECK(height(m.v_template) < 1.85);
  auto J = torch::matmul(m.J_regressor, m.v_template);
  CHECK(J[0].abs().max().item<double>() < 1e-9);
  CHECK(J[15][1].item<double>() > J[12][1].item<double>());  // head above neck
  CHECK(J[20][0].item<double>() > 0.6);                      // left wrist at +x
  CHECK(J[21][0].item<double>() < -0.6);
  CHECK(std::abs(J[20][1].item<double>() - J[16][1].item<double>()) < 0.02);  // arms level
  // Each part is a closed surface with outward faces.
  auto faces = m.faces;
  auto part_of_face = bt.vertex_part.index_select(0, faces.select(1, 0));
  for (int p = 0; p < kNumParts; ++p) {
    auto f = faces.index({part_of_face == p});
    INFO(part_name(static_cast<Part>(p)));
    CHECK(closed(f));
    CHECK(th::geometry::signed_volume(m.v_template, f) > 0);
  }
}

TEST_CASE("shape directions mean what they say and joints follow the shape", "[synth][body]") {
  const BodyTemplate bt = build_body_template();
  const auto& m = bt.model;
  auto shaped = [&](int k, double amount) {
    auto beta = torch::zeros({10}, torch::kFloat64);
    beta[k] = amount;
    return th::body::lbs(m, torch::zeros({72}, torch::kFloat64), beta);
  };
  auto base = shaped(0, 0.0);
  auto dist = [](const torch::Tensor& J, int a, int b) {
    return (J[a] - J[b]).norm().item<double>();
  };
  // 0: stature.
  CHECK(height(shaped(0, 1.0).vertices) > height(base.vertices) + 0.04);
  // 1: girth: the waist ring gets wider.
  auto waist_width = [&](const torch::Tensor& v) {
    auto mask = ((v.select(1, 1) - 0.11).abs() < 0.02) & (bt.vertex_part == int(Part::Torso));
    return v.index({mask}).select(1, 0).max().item<double>();
  };
  CHECK(waist_width(shaped(1, 1.0).vertices) > waist_width(base.vertices) + 0.015);
  // 2: shoulders; 3: hips; 4: legs; 5: arms; 6: torso; 8: head.
  CHECK(dist(shaped(2, 1.0).joints, 16, 17) > dist(base.joints, 16, 17) + 0.03);
  CHECK(dist(shaped(3, 1.0).joints, 1, 2) > dist(base.joints, 1, 2) + 0.02);
  CHECK(dist(shaped(4, 1.0).joints, 1, 7) > dist(base.joints, 1, 7) + 0.04);
  CHECK(dist(shaped(5, 1.0).joints, 16, 20) > dist(base.joints, 16, 20) + 0.03);
  CHECK(dist(shaped(6, 1.0).joints, 0, 12) > dist(base.joints, 0, 12) + 0.025);
  auto head_top = [](const torch::Tensor& v) { return v.select(1, 1).max().item<double>(); };
  CHECK(head_top(shaped(8, 1.0).vertices) > head_top(base.vertices) + 0.01);
  // Joints stay centred in their rings under any shape: the knee stays between the leg's
  // front and back surfaces.
  torch::manual_seed(2);
  auto beta = torch::randn({10}, torch::kFloat64) * 2.0;
  auto r = th::body::lbs(m, torch::zeros({72}, torch::kFloat64), beta);
  const auto& leg = bt.layout(Part::LegL);
  const int knee_ring = leg.ring_at(-bt.landmarks.knee_y);
  auto ring = torch::stack(
      {r.v_shaped[leg.vertex(knee_ring, 0)], r.v_shaped[leg.vertex(knee_ring, leg.segments / 2)]});
  CHECK(torch::allclose(ring.mean(0), r.joints[4], 0, 1e-9));
}

TEST_CASE("Rng streams are reproducible and independent", "[synth]") {
  Rng a = Rng::stream(5, 1), b = Rng::stream(5, 1), c = Rng::stream(5, 2);
  for (int i = 0; i < 10; ++i) CHECK(a.bits() == b.bits());
  CHECK(Rng::stream(5, 1).bits() != c.bits());
  Rng r(42);
  double sum = 0, sq = 0;
  for (int i = 0; i < 20000; ++i) {
    const double x = r.normal();
    sum += x, sq += x * x;
  }
  CHECK(std::abs(sum / 20000) < 0.03);
  CHECK(std::abs(sq / 20000 - 1.0) < 0.05);
  for (int i = 0; i < 1000; ++i) CHECK(r.below(7) < 7);
}

TEST_CASE("folder layouts follow ZJU-MoCap's three naming schemes", "[synth]") {
  CHECK(FolderLayout::style_for("CoreView_313") == FolderStyle::Original21);
  CHECK(FolderLayout::style_for("CoreView_396") == FolderStyle::Params396);
  CHECK(FolderLayout::style_for("CoreView_s04") == FolderStyle::Standard);
  FolderLayout standard("CoreView_s04", FolderStyle::Standard, {0, 1, 2});
  CHECK(standard.image_path(7, 2) == "Camera_B3/000007.jpg");
  CHECK(standard.mask_path("mask_cihp", 7, 2) == "mask_cihp/Camera_B3/000007.png");
  CHECK(standard.params_path(7) == "new_params/7.npy");
  CHECK(standard.vertices_path(7) == "new_vertices/7.npy");
  const auto idx = cameras_21(23);
  REQUIRE(idx.size() == 21);
  CHECK(idx[18] == 18);
  CHECK(idx[19] == 21);
  CHECK(idx[20] == 22);
  FolderLayout original("CoreView_313", FolderStyle::Original21, idx);
  CHECK(original.camera_folder(20) == "Camera (23)");
  CHECK(original.image_path(0, 0) ==
        "Camera (1)/CoreView_313_Camera_(1)_0001_2019-08-23_16-08-50.599.jpg");
  CHECK(original.params_path(0) == "new_params/1.npy");
  FolderLayout p396("CoreView_396", FolderStyle::Params396, {0});
  CHECK(p396.params_path(3) == "params/3.npy");
  CHECK(p396.vertices_path(3) == "vertices/3.npy");
}

TEST_CASE("mask PNGs read back unchanged", "[synth]") {
  cv::Mat m(37, 53, CV_8U, cv::Scalar(0));
  cv::rectangle(m, {5, 6}, {30, 20}, cv::Scalar(1), cv::FILLED);
  m.at<uint8_t>(36, 52) = 19;
  const std::string bytes = encode_mask_png(m);
  cv::Mat back = cv::imdecode(std::vector<uchar>(bytes.begin(), bytes.end()), cv::IMREAD_UNCHANGED);
  REQUIRE(back.type() == CV_8U);
  CHECK(cv::countNonZero(back != m) == 0);
}

TEST_CASE("default.yaml states the defaults and data_splits/synthetic.yaml is its split",
          "[synth]") {
  const auto from_file = th::config::load<SynthConfig>("configs/synth/default.yaml");
  CHECK(config_text(from_file) == config_text(SynthConfig{}));
  CHECK(read_all("data_splits/synthetic.yaml") == split_yaml(from_file));
  const std::string split = split_yaml(from_file);
  CHECK(split.find("      - {name: CoreView_s08, begin: 0, ni: 60, interval: 10}") !=
        std::string::npos);
  CHECK(split.find("  training:\n    reference_views: random\n    num_reference_views: 3\n"
                   "    target_views: all\n") != std::string::npos);
  CHECK(split.find("reference_views: [0, 7, 15]") != std::string::npos);
  CHECK(split.find("target_views: [3, 5, 10, 12, 18, 20]") != std::string::npos);
  CHECK_THROWS_WITH(tiny({"frames=0"}),
                    Catch::Contains("config key 'frames' = 0: must be >= 1 (frames per person)"));
  CHECK_THROWS_WITH(tiny({"people.unseen=[CoreView_313]"}), Catch::Contains("CoreView_313"));
}

TEST_CASE(
    "tiny dataset with noise off: numpy finds METHOD 1.1's structure and vertices fall in "
    "the masks and cameras lie on the ring",
    "[synth][python]") {
  const auto dir = th::test::scratch_dir("synth_geometry");
  const Summary s = generate(tiny({"noise.enabled=false"}), dir / "data", false);
  CHECK(s.people == 3);
  CHECK(s.images == 4 * (21 + 23 + 23));
  // Structure at the tiny size; mask geometry at 256 x 256, where limbs are several pixels
  // wide (at 128 x 128 an arm is 4 px and its rim vertices are half of it).
  CHECK(th::test::run_python("tests/python/check_synth.py",
                             (dir / "data").string() + " --ring 3.0 0.08") == 0);
  generate(tiny({"noise.enabled=false", "image.width=256", "image.height=256", "frames=2",
                 "split.train_frames=1"}),
           dir / "data256", false);
  CHECK(fs::exists(dir / "data" / "contact_sheet.png"));
  CHECK(fs::exists(dir / "data" / "split.yaml"));
  CHECK(th::test::run_python("tests/python/check_synth.py",
                             (dir / "data256").string() + " --noise-free --ring 3.0 0.08") == 0);
}

TEST_CASE("annots and params read back in C++ equal to numpy's reading", "[synth][python]") {
  const auto dir = th::test::scratch_dir("synth_readback");
  generate(tiny(), dir / "data", false);
  fs::create_directories(dir / "numpy");
  REQUIRE(th::test::run_python("tests/python/check_synth.py",
                               (dir / "data").string() + " --resave " + (dir / "numpy").string()) ==
          0);
  for (const char* human : {"CoreView_313", "CoreView_396", "CoreView_s03"}) {
    INFO(human);
    const auto ours = dir / "data" / human / "annots.npy";
    const auto numpy = dir / "numpy" / (std::string(human) + "_annots.npy");
    CHECK(th::io::read_npy_value(ours) == th::io::read_npy_value(numpy));
    CHECK(th::test::byte_difference(read_all(ours), read_all(numpy)) ==
          "");  // np.save of what numpy read
    const std::string params = std::string(human) == "CoreView_396"   ? "params/0.npy"
                               : std::string(human) == "CoreView_313" ? "new_params/1.npy"
                                                                      : "new_params/0.npy";
    const auto p_numpy = dir / "numpy" / (std::string(human) + "_params.npy");
    CHECK(th::io::read_npy_value(dir / "data" / human / params) == th::io::read_npy_value(p_numpy));
    CHECK(th::test::byte_difference(read_all(dir / "data" / human / params), read_all(p_numpy)) ==
          "");
  }
  // The annots hold what METHOD 1.1 says: T in millimetres, K for the written size.
  const auto a = th::io::read_npy_value(dir / "data" / "CoreView_s03" / "annots.npy");
  const auto T = a["cams"]["T"].at(0).as_tensor();
  CHECK(T.sizes() == torch::IntArrayRef({3, 1}));
  CHECK(T.norm().item<double>() > 2500.0);
  CHECK(a["cams"]["K"].at(0).as_tensor()[0][2].item<double>() == Approx(63.5).margin(5.0));
  CHECK(a["ims"].size() == 4);
}

TEST_CASE("published vertices are the body model's LBS of the published (noisy) params",
          "[synth]") {
  const auto dir = th::test::scratch_dir("synth_noise");
  generate(tiny(), dir / "noisy", false);
  generate(tiny({"noise.enabled=false"}), dir / "clean", false);
  const auto model = th::body::load_smpl(dir / "noisy" / "smpl_model.npz");
  for (int f = 0; f < 4; ++f) {
    const auto noisy = th::io::read_npy_value(dir / "noisy" / "CoreView_s03" / "new_params" /
                                              (std::to_string(f) + ".npy"));
    const auto clean = th::io::read_npy_value(dir / "clean" / "CoreView_s03" / "new_params" /
                                              (std::to_string(f) + ".npy"));
    const auto r = th::body::lbs(model, noisy["poses"].as_tensor(), noisy["shapes"].as_tensor());
    const auto world =
        th::body::smpl_to_world(r.vertices, noisy["Rh"].as_tensor(), noisy["Th"].as_tensor());
    const auto published = th::io::read_npy(dir / "noisy" / "CoreView_s03" / "new_vertices" /
                                            (std::to_string(f) + ".npy"));
    CHECK(torch::allclose(world.to(torch::kFloat32), published, 0, 1e-5));
    // The fitting error: poses differ by a few degrees, shapes are the same.
    const double dp =
        (noisy["poses"].as_tensor() - clean["poses"].as_tensor()).abs().max().item<double>();
    CHECK(dp > 0.01);
    CHECK(dp < 0.3);
    CHECK(torch::equal(noisy["shapes"].as_tensor(), clean["shapes"].as_tensor()));
    CHECK((noisy["poses"].as_tensor().slice(1, 0, 3).abs().max().item<double>()) == 0.0);
  }
}

TEST_CASE("same seed gives byte-identical files whatever the threads and another seed other people",
          "[synth]") {
  const auto dir = th::test::scratch_dir("synth_determinism");
  generate(tiny({"threads=1"}), dir / "a", false);
  generate(tiny({"threads=2"}), dir / "b", false);
  generate(tiny({"seed=2"}), dir / "c", false);
  auto a = snapshot(dir / "a"), b = snapshot(dir / "b"), c = snapshot(dir / "c");
  a.erase("synth_config.yaml"), b.erase("synth_config.yaml"), c.erase("synth_config.yaml");
  REQUIRE(a.size() > 300);
  CHECK(a.size() == b.size());
  int differing = 0;
  for (const auto& [name, bytes] : a) differing += b.count(name) == 0 || b[name] != bytes;
  CHECK(differing == 0);
  // Another seed: other shapes, other images (the body model itself is shared).
  CHECK(c["smpl_model.npz"] == a["smpl_model.npz"]);
  const auto shapes = [&](const fs::path& root) {
    return th::io::read_npy_value(root / "CoreView_s03" / "new_params" / "0.npy")["shapes"]
        .as_tensor();
  };
  CHECK(!torch::allclose(shapes(dir / "a"), shapes(dir / "c")));
  CHECK(a["CoreView_s03/Camera_B1/000000.jpg"] != c["CoreView_s03/Camera_B1/000000.jpg"]);
}

TEST_CASE("an existing folder with the same config is skipped and another is refused unless forced",
          "[synth]") {
  const auto dir = th::test::scratch_dir("synth_existing") / "data";
  const auto config = tiny({"frames=2", "split.train_frames=1"});
  CHECK_FALSE(generate(config, dir, false).skipped);
  CHECK(generate(config, dir, false).skipped);
  const auto other = tiny({"frames=2", "split.train_frames=1", "seed=9"});
  CHECK_THROWS_AS(generate(other, dir, false), th::Error);
  CHECK_THROWS_WITH(generate(other, dir, false), Catch::Contains("--force"));
  CHECK_FALSE(generate(other, dir, true).skipped);
  CHECK(read_all(dir / "synth_config.yaml") == config_text(other));
  // A non-empty folder that is not a finished dataset.
  const auto foreign = dir.parent_path() / "foreign";
  fs::create_directories(foreign);
  std::ofstream(foreign / "notes.txt") << "keep";
  CHECK_THROWS_WITH(generate(config, foreign, false), Catch::Contains("not empty"));
  CHECK_FALSE(generate(config, foreign, true).skipped);
  CHECK(fs::exists(foreign / "notes.txt"));
}
