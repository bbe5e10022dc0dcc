#include <catch2/catch.hpp>
#include <cstdio>
#include <fstream>

#include "body/smpl.hpp"
#include "core/error.hpp"
#include "data/dataset.hpp"
#include "data/split.hpp"
#include "io/npy.hpp"
#include "support/test_env.hpp"

namespace fs = std::filesystem;
using th::io::Value;

namespace {

// Writes <root>/<name>/annots.npy for `frames` frames of `cameras` cameras (ZJU-MoCap names).
void write_annots(const fs::path& root, const std::string& name, int frames, int cameras) {
  Value::List K, R, T, D, ims;
  for (int c = 0; c < cameras; ++c) {
    K.push_back(Value::array(
        torch::tensor({500.0, 0.0, 256.0, 0.0, 500.0, 256.0, 0.0, 0.0, 1.0}, torch::kFloat64)
            .reshape({3, 3})));
    R.push_back(Value::array(torch::eye(3, torch::kFloat64)));
    T.push_back(Value::array(torch::zeros({3, 1}, torch::kFloat64)));
    D.push_back(Value::array(torch::zeros({5, 1}, torch::kFloat64)));
  }
  char buf[64];
  for (int f = 0; f < frames; ++f) {
    Value::List paths;
    for (int c = 0; c < cameras; ++c) {
      std::snprintf(buf, sizeof buf, "Camera_B%d/%06d.jpg", c + 1, f);
      paths.push_back(Value::str(buf));
    }
    ims.push_back(Value::dict({{Value::str("ims"), Value::list(paths)}}));
  }
  const Value cams = Value::dict({{Value::str("K"), Value::list(K)},
                                  {Value::str("R"), Value::list(R)},
                                  {Value::str("T"), Value::list(T)},
                                  {Value::str("D"), Value::list(D)}});
  fs::create_directories(root / name);
  th::io::write_npy_value(
      root / name / "annots.npy",
      Value::dict({{Value::str("cams"), cams}, {Value::str("ims"), Value::list(ims)}}));
}

size_t samples(const fs::path& root, const std::string& split, const std::string& setting,
               th::DatasetKind dataset = th::DatasetKind::zju_mocap) {
  th::DataConfig c;
  c.root = root.string();
  c.dataset = dataset;
  c.split_file = split;
  auto smpl = std::make_shared<const th::body::SmplModel>();
  return th::data::Dataset(c, setting, th::data::Dataset::Mode::Test, smpl).size();
}

}  // namespace

TEST_CASE("ZJU-MoCap split sizes match the paper for annots of the real lengths", "[split]") {
  const fs::path root = th::test::scratch_dir("zju_split_sizes");
  // Frames and cameras of the released captures.
  const std::vector<std::tuple<std::string, int, int>> humans = {
      {"CoreView_313", 1470, 21}, {"CoreView_315", 2185, 21}, {"CoreView_377", 617, 23},
      {"CoreView_386", 646, 23},  {"CoreView_387", 654, 23},  {"CoreView_390", 1171, 23},
      {"CoreView_392", 556, 23},  {"CoreView_393", 658, 23},  {"CoreView_394", 859, 23},
      {"CoreView_396", 1350, 23}};
  for (const auto& [name, frames, cameras] : humans) write_annots(root, name, frames, cameras);
  const std::string split = "data_splits/zju_mocap.yaml";
  CHECK(samples(root, split, "training") == 7589);
  CHECK(samples(root, split, "pose") == 798);
  CHECK(samples(root, split, "identity") == 438);
  CHECK(samples(root, split, "one_shot") == 438);
  CHECK(samples(root, split, "fitting") > 0);
}

TEST_CASE("the H36M cross-dataset split has 54 target images", "[split]") {
  const fs::path root = th::test::scratch_dir("h36m_split_sizes");
  for (const auto& [name, frames] : std::vector<std::pair<std::string, int>>{{"S1", 750},
                                                                             {"S5", 1250},
                                                                             {"S6", 750},
                                                                             {"S7", 1500},
                                                                             {"S8", 1250},
                                                                             {"S9", 1300},
                                                                             {"S11", 1000}})
    write_annots(root / name, "Posing", frames, 4);  // Animatable NeRF's <S>/Posing layout
  CHECK(samples(root, "data_splits/h36m.yaml", "cross_dataset", th::DatasetKind::h36m) == 54);
  // data.dataset names the layout: the H36M folders read as ZJU-MoCap fail naming the key.
  CHECK_THROWS_WITH(
      samples(root, "data_splits/h36m.yaml", "cross_dataset", th::DatasetKind::zju_mocap),
      Catch::Contains((root / "S1" / "annots.npy").string()) &&
          Catch::Contains("data.dataset: h36m"));
}

TEST_CASE("ZJU-MoCap folders read as H36M fail naming data.dataset", "[split]") {
  const fs::path root = th::test::scratch_dir("zju_as_h36m");
  write_annots(root, "CoreView_387", 30, 23);
  CHECK_THROWS_WITH(samples(root, "data_splits/zju_mocap.yaml", "identity", th::DatasetKind::h36m),
                    Catch::Contains((root / "CoreView_387" / "Posing" / "annots.npy").string()) &&
                        Catch::Contains("data.dataset: zju_mocap"));
}

TEST_CASE("an unknown setting or a missing human folder is named in the error", "[split]") {
  const fs::path root = th::test::scratch_dir("split_errors");
  CHECK_THROWS_WITH(samples(root, "data_splits/zju_mocap.yaml", "poze"),
                    Catch::Contains("no setting 'poze'") && Catch::Contains("identity"));
  CHECK_THROWS_WITH(samples(root, "data_splits/zju_mocap.yaml", "identity"),
                    Catch::Contains("CoreView_387") && Catch::Contains("does not exist"));
  write_annots(root, "CoreView_387", 30, 5);
  CHECK_THROWS_WITH(
      samples(root, "data_splits/zju_mocap.yaml", "identity"),
      Catch::Contains("reference_views: camera 7 does not exist for CoreView_387 (5 cameras"));
}

TEST_CASE("split integers are decimal and person names hold no control character or formula",
          "[split]") {
  const fs::path dir = th::test::scratch_dir("split_names");
  auto split_with = [&](const std::string& human, const std::string& begin) {
    const fs::path file = dir / "split.yaml";
    std::ofstream(file)
        << "settings:\n  s:\n    reference_views: [0, 07]\n    target_views: [010]\n    humans:\n"
        << "      - {name: " << human << ", begin: " << begin << ", ni: 2, interval: 1}\n";
    return file;
  };
  const auto s = th::data::load_split(split_with("CoreView_1", "010"), "s");
  CHECK(s.humans.at(0).begin == 10);
  // Plain numbers are decimal calibration indices.
  CHECK(s.reference_views == std::vector<th::data::CameraRef>{{"0", true}, {"07", true}});
  CHECK(s.target_views == std::vector<th::data::CameraRef>{{"010", true}});
  CHECK_THROWS_WITH(th::data::load_split(split_with("CoreView_1", "0x10"), "s"),
                    Catch::Contains("humans[0]: 'begin' must be a decimal integer"));
  CHECK_THROWS_WITH(th::data::load_split(split_with("\"Core\\nView\"", "0"), "s"),
                    Catch::Contains("split file '" + (dir / "split.yaml").string() +
                                    "', setting 's', humans[0]") &&
                        Catch::Contains("holds a control character (0x0a)"));
  CHECK_THROWS_WITH(th::data::load_split(split_with("\"Core\\tView\"", "0"), "s"),
                    Catch::Contains("control character (0x09)"));
  for (const char* formula : {"\"=cmd|' /C calc'!A0\"", "\"+1\"", "\"-1\"", "\"@SUM(1)\""})
    CHECK_THROWS_WITH(th::data::load_split(split_with(formula, "0"), "s"),
                      Catch::Contains("spreadsheets read as a formula"));
  CHECK(th::data::load_split(split_with("\"Core,View \\\"1\\\"\"", "0"), "s").humans.at(0).name ==
        "Core,View \"1\"");
}
