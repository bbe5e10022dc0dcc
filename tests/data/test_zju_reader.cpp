#include <catch2/catch.hpp>
#include <fstream>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "body/smpl.hpp"
#include "core/error.hpp"
#include "data/dataset.hpp"
#include "data/zju_mocap.hpp"
#include "geometry/camera.hpp"
#include "io/npy.hpp"
#include "support/test_env.hpp"

namespace fs = std::filesystem;
using namespace th::data;

namespace {

th::DataConfig tiny_config(const fs::path& root) {
  th::DataConfig c;
  c.root = root.string();
  c.split_file = (root / "split.yaml").string();
  c.workers = 0;
  return c;
}

std::shared_ptr<const Dataset> open(const fs::path& root, const std::string& setting,
                                    Dataset::Mode mode = Dataset::Mode::Test, double ratio = 0.5) {
  auto c = tiny_config(root);
  c.ratio = ratio;
  return std::make_shared<const Dataset>(c, setting, mode, load_body_model(c));
}

// A private copy of the tiny dataset that a test may damage.
fs::path copy_of_tiny(const std::string& name) {
  const fs::path dst = th::test::scratch_dir(name);
  fs::copy(th::test::tiny_dataset(), dst,
           fs::copy_options::recursive | fs::copy_options::overwrite_existing);
  return dst;
}

}  // namespace

TEST_CASE("a training sample of synthetic data has consistent shapes and rays", "[dataset]") {
  REQUIRE(fs::exists(th::test::tiny_dataset() / "split.yaml"));
  const auto ds = open(th::test::tiny_dataset(), "training", Dataset::Mode::Train);
  REQUIRE(ds->size() > 0);
  const Sample s = ds->load(0, 123);
  const int64_t nv = ds->smpl().num_vertices();
  CHECK(s.reference_views.size() == 3);
  CHECK(s.ref_images.sizes() == torch::IntArrayRef({3, 3, 64, 64}));
  CHECK(s.visibility.sizes() == torch::IntArrayRef({3, nv}));
  CHECK(s.body.A.sizes() == torch::IntArrayRef({nv, 3, 3}));
  CHECK(s.patch_rgb.sizes() == torch::IntArrayRef({6, 3, 20, 20}));
  const int64_t n = s.ray_o.size(0);
  REQUIRE(n > 0);
  CHECK(n <= 6 * 400);
  CHECK((s.far > s.near).all().item<bool>());
  // Each ray's colour is its target pixel and its patch slot holds the same colour.
  CHECK(torch::equal(s.ray_rgb, s.target_image.reshape({-1, 3}).index({s.ray_pixel})));
  const auto slots = s.patch_rgb.permute({0, 2, 3, 1}).reshape({-1, 3}).index({s.ray_patch_index});
  CHECK(torch::equal(slots, s.ray_rgb));
  // Background is black outside the (banded) mask.
  CHECK(s.target_image.index({s.target_mask == 0}).abs().max().item<float>() == 0.0f);
}

TEST_CASE("the same seed gives the same sample and another seed another draw", "[dataset]") {
  const auto ds = open(th::test::tiny_dataset(), "training", Dataset::Mode::Train);
  const Sample a = ds->load(3, 7), b = ds->load(3, 7), c = ds->load(3, 8);
  CHECK(a.reference_views == b.reference_views);
  CHECK(torch::equal(a.ray_pixel, b.ray_pixel));
  CHECK(torch::equal(a.ref_images, b.ref_images));
  CHECK((a.reference_views != c.reference_views || !torch::equal(a.ray_pixel, c.ray_pixel)));
}

TEST_CASE("test samples render every in-box pixel of the target view", "[dataset]") {
  const auto ds = open(th::test::tiny_dataset(), "identity");
  const Sample s = ds->load(0, 0);
  CHECK(s.reference_views == std::vector<int>({0, 7, 15}));
  CHECK(s.box_mask.sum().item<int64_t>() == s.ray_o.size(0));
  CHECK(s.ray_o.size(0) > 200);
  // The person lies inside the box: every person pixel has a valid ray.
  const auto person = s.target_mask == 1;
  CHECK((s.box_mask | ~person).all().item<bool>());
}

TEST_CASE("visible body vertices project inside the person's mask", "[dataset][visibility]") {
  // Exact fits (no fitting noise): the body lies inside the clothed silhouette; where skin is
  // the surface, silhouette vertices sit on the mask's edge, hence the 1-pixel tolerance.
  // Full resolution of the tiny data (128 px): at 64 px an arm is two pixels wide.
  const auto ds =
      open(th::test::tiny_dataset(/*exact=*/true), "identity", Dataset::Mode::Test, 1.0);
  const auto& human = *ds->humans()[0];
  const Sample s = ds->load(0, 0);
  for (size_t v = 0; v < s.reference_views.size(); ++v) {
    const ViewImage view = load_view(human, s.frame, s.reference_views[v], {1.0, false, nullptr});
    const auto vis = s.visibility[v];
    const auto uv = th::geometry::project_points(s.body.vertices.index({vis}), s.ref_K[v],
                                                 s.ref_R[v], s.ref_T[v]);
    const auto px = torch::round(uv).to(torch::kInt64);
    int inside = 0;
    auto a = px.accessor<int64_t, 2>();
    cv::Mat mask;
    cv::dilate(view.mask, mask, cv::Mat::ones(3, 3, CV_8U));
    for (int64_t i = 0; i < px.size(0); ++i) {
      const int64_t x = std::clamp<int64_t>(a[i][0], 0, view.mask.cols - 1);
      const int64_t y = std::clamp<int64_t>(a[i][1], 0, view.mask.rows - 1);
      inside += mask.at<uint8_t>(int(y), int(x)) != 0;
    }
    const double frac = double(inside) / double(px.size(0));
    INFO("view " << s.reference_views[v] << ": " << px.size(0) << " visible vertices, " << frac
                 << " inside the mask");
    CHECK(px.size(0) > 0.2 * ds->smpl().num_vertices());
    CHECK(frac >= 0.98);
  }
}

TEST_CASE("CoreView_313 images resolve under original and renamed names", "[dataset]") {
  const fs::path root = copy_of_tiny("renamed_313");
  const fs::path cam = root / "CoreView_313" / "Camera (1)";
  for (const auto& e : fs::directory_iterator(cam)) {
    const int n = frame_number_of(e.path().filename().string());
    char name[16];
    std::snprintf(name, sizeof name, "%04d.jpg", n);
    fs::rename(e.path(), cam / name);  // the usual renaming, annots.npy untouched
  }
  auto human = ZjuMocapSequence::open(root / "CoreView_313");
  CHECK(human->image_path(0, 0).filename() == "0001.jpg");
  CHECK(human->image_path(0, 1).filename().string().rfind("CoreView_313_Camera_(2)_0001", 0) == 0);
  CHECK(human->frame_number(0) == 1);
  CHECK(frame_number_of("CoreView_313_Camera_(1)_0012_2019-08-23_16-08-50.592.jpg") == 12);
  CHECK(frame_number_of("000123.jpg") == 123);
  CHECK(frame_number_of("notes.txt") == -1);
  CHECK_NOTHROW(load_view(*human, 0, 0, {}));
}

TEST_CASE("bad data fails with an error naming the file", "[dataset][errors]") {
  const fs::path root = copy_of_tiny("bad_data");
  const auto c = tiny_config(root);
  const auto smpl = load_body_model(c);
  auto load_first = [&](const std::string& setting) {
    Dataset(c, setting, Dataset::Mode::Test, smpl).load(0, 0);
  };

  SECTION("a missing camera folder") {
    fs::remove_all(root / "CoreView_s03" / "Camera_B1");
    CHECK_THROWS_WITH(load_first("identity"),
                      Catch::Contains("Camera_B1") && Catch::Contains("missing"));
  }
  SECTION("a params file with a wrong shape") {
    th::io::Value::Dict d;
    d.emplace_back(th::io::Value::str("poses"),
                   th::io::Value::array(torch::zeros({1, 69}, torch::kFloat64)));
    d.emplace_back(th::io::Value::str("Rh"),
                   th::io::Value::array(torch::zeros({1, 3}, torch::kFloat64)));
    d.emplace_back(th::io::Value::str("Th"),
                   th::io::Value::array(torch::zeros({1, 3}, torch::kFloat64)));
    d.emplace_back(th::io::Value::str("shapes"),
                   th::io::Value::array(torch::zeros({1, 10}, torch::kFloat64)));
    const fs::path file = root / "CoreView_s03" / "new_params" / "0.npy";
    th::io::write_npy_value(file, th::io::Value::dict(d));
    CHECK_THROWS_WITH(load_first("identity"),
                      Catch::Contains(file.string()) && Catch::Contains("'poses' has 69 values"));
  }
  SECTION("fewer images than annots lists") {
    const fs::path img = root / "CoreView_s03" / "Camera_B8" / "000000.jpg";
    fs::remove(img);
    CHECK_THROWS_WITH(load_first("identity"),
                      Catch::Contains(img.string()) && Catch::Contains("missing"));
  }
  SECTION("a corrupt image") {
    const fs::path img = root / "CoreView_s03" / "Camera_B4" / "000000.jpg";
    std::ofstream(img, std::ios::binary | std::ios::trunc) << "not a jpeg";
    CHECK_THROWS_WITH(load_first("identity"),
                      Catch::Contains(img.string()) && Catch::Contains("corrupt"));
  }
  SECTION("a truncated image") {
    const fs::path img = root / "CoreView_s03" / "Camera_B4" / "000000.jpg";
    std::ifstream in(img, std::ios::binary);
    const std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    in.close();
    std::ofstream(img, std::ios::binary | std::ios::trunc) << bytes.substr(0, bytes.size() * 2 / 3);
    CHECK_THROWS_WITH(load_first("identity"),
                      Catch::Contains(img.string()) && Catch::Contains("truncated"));
  }
  SECTION("mask and mask_cihp of different sizes") {
    const fs::path a = root / "CoreView_s03" / "mask" / "Camera_B1" / "000000.png";
    const fs::path b = root / "CoreView_s03" / "mask_cihp" / "Camera_B1" / "000000.png";
    const fs::path present = fs::exists(a) ? a : b, other = fs::exists(a) ? b : a;
    fs::create_directories(other.parent_path());
    cv::imwrite(other.string(), cv::Mat::zeros(17, 23, CV_8U));
    CHECK_THROWS_WITH(load_first("identity"),
                      Catch::Contains(other.string()) && Catch::Contains("23x17"));
  }
  SECTION("a missing mask") {
    fs::remove_all(root / "CoreView_s03" / "mask");
    fs::remove_all(root / "CoreView_s03" / "mask_cihp");
    CHECK_THROWS_WITH(load_first("identity"), Catch::Contains("no mask for"));
  }
  SECTION("a non-finite vertex") {
    const fs::path file = root / "CoreView_s03" / "new_vertices" / "0.npy";
    auto v = th::io::read_npy(file).clone();
    v[5][1] = std::nan("");
    th::io::write_npy(file, v);
    CHECK_THROWS_WITH(load_first("identity"), Catch::Contains(file.string()) &&
                                                  Catch::Contains("nan") &&
                                                  Catch::Contains("index 16"));
  }
  SECTION("a non-finite global translation") {
    th::io::Value::Dict d;
    d.emplace_back(th::io::Value::str("poses"),
                   th::io::Value::array(torch::zeros({1, 72}, torch::kFloat64)));
    d.emplace_back(th::io::Value::str("Rh"),
                   th::io::Value::array(torch::zeros({1, 3}, torch::kFloat64)));
    d.emplace_back(th::io::Value::str("Th"),
                   th::io::Value::array(torch::full({1, 3}, INFINITY, torch::kFloat64)));
    d.emplace_back(th::io::Value::str("shapes"),
                   th::io::Value::array(torch::zeros({1, 10}, torch::kFloat64)));
    const fs::path file = root / "CoreView_s03" / "new_params" / "0.npy";
    th::io::write_npy_value(file, th::io::Value::dict(d));
    CHECK_THROWS_WITH(load_first("identity"), Catch::Contains(file.string()) &&
                                                  Catch::Contains("'Th'") &&
                                                  Catch::Contains("inf"));
  }
  SECTION("a vertices file of another body model") {
    const fs::path file = root / "CoreView_s03" / "new_vertices" / "0.npy";
    th::io::write_npy(file, torch::zeros({10, 3}));
    CHECK_THROWS_WITH(load_first("identity"),
                      Catch::Contains("10 vertices") && Catch::Contains("body model"));
  }
}

TEST_CASE("the prefetcher returns the samples of its order and rethrows load errors",
          "[dataset][prefetch]") {
  const auto ds = open(th::test::tiny_dataset(), "training", Dataset::Mode::Train);
  const std::vector<size_t> order = {5, 1, 9, 1};
  const std::vector<uint64_t> seeds = {1, 2, 3, 4};
  Prefetcher p(ds, order, seeds, 2, 2);
  for (size_t i = 0; i < order.size(); ++i) {
    const Sample s = p.next();
    const Sample direct = ds->load(order[i], seeds[i]);
    CHECK(torch::equal(s.ray_pixel, direct.ray_pixel));
    CHECK(s.reference_views == direct.reference_views);
  }
  CHECK(p.done());
  Prefetcher bad(ds, {0, 999999}, {0, 0}, 1, 2);
  CHECK_NOTHROW(bad.next());
  CHECK_THROWS(bad.next());
}

TEST_CASE("visibility files are found by frame number, zero-padded like the renamed images",
          "[dataset][visibility][parity]") {
  const fs::path root = copy_of_tiny("visibility_files");
  const fs::path vis_root = root / "zju_rasterization";
  // The zju_rasterization names: Camera_B<k>/%06d.npy, and for CoreView_313/315 (whose images
  // keep their original long names here) Camera (<k>)/%04d.npy of the 1-based frame number.
  const auto h313 = ZjuMocapSequence::open(root / "CoreView_313");
  CHECK(h313->image_path(0, 0).filename().string().rfind("CoreView_313_Camera_(1)_0001", 0) == 0);
  CHECK(visibility_file(vis_root, *h313, 0, 0) ==
        vis_root / "CoreView_313" / "visibility" / "Camera (1)" / "0001.npy");
  CHECK(visibility_file(vis_root, *h313, 1, 2) ==
        vis_root / "CoreView_313" / "visibility" / "Camera (3)" / "0002.npy");
  const auto s03 = ZjuMocapSequence::open(root / "CoreView_s03");
  CHECK(visibility_file(vis_root, *s03, 0, 4) ==
        vis_root / "CoreView_s03" / "visibility" / "Camera_B5" / "000000.npy");

  // Files for every view of every person: the dataset reads them as they are.
  auto c = tiny_config(root);
  c.visibility = th::VisibilitySource::files;
  c.visibility_root = vis_root.string();
  const auto smpl = load_body_model(c);
  const int64_t nv = smpl->num_vertices();
  torch::manual_seed(3);
  std::map<fs::path, torch::Tensor> written;
  for (const char* name : {"CoreView_313", "CoreView_396", "CoreView_s03"}) {
    const auto human = ZjuMocapSequence::open(root / name);
    for (int f = 0; f < human->num_frames(); ++f)
      for (int k = 0; k < human->num_cameras(); ++k) {
        const fs::path file = visibility_file(vis_root, *human, f, k);
        fs::create_directories(file.parent_path());
        const auto vis = torch::rand({nv}) < 0.5;
        th::io::write_npy(file, vis);
        written[file] = vis;
      }
  }
  const Dataset ds(c, "identity", Dataset::Mode::Test, smpl);
  const Sample s = ds.load(0, 0);
  const auto human = ds.humans()[0];
  for (size_t v = 0; v < s.reference_views.size(); ++v)
    CHECK(
        torch::equal(s.visibility[int64_t(v)],
                     written.at(visibility_file(vis_root, *human, s.frame, s.reference_views[v]))));

  // A missing file is an error naming it, unless all-visible is asked for explicitly.
  const fs::path missing = visibility_file(vis_root, *human, s.frame, s.reference_views[1]);
  fs::remove(missing);
  CHECK_THROWS_WITH(ds.load(0, 0), Catch::Contains(missing.string()) && Catch::Contains("missing"));
  c.visibility_missing = th::MissingVisibility::all_visible;
  const Sample lenient = Dataset(c, "identity", Dataset::Mode::Test, smpl).load(0, 0);
  CHECK(lenient.visibility[1].all().item<bool>());
  CHECK(torch::equal(lenient.visibility[0], s.visibility[0]));
}

TEST_CASE("the target mask's border band is marked before undistortion, as the reference does",
          "[dataset][parity]") {
  // METHOD 2.1 step 6 [parity]: band on the distorted mask, then both undistorted (bilinear), so
  // edge pixels hold blends of 0, 1 and 100; the background is black where the result is 0.
  const fs::path root = copy_of_tiny("band_parity");
  const fs::path dir = root / "CoreView_s03";
  REQUIRE(th::test::run_python("tests/python/view_reference.py",
                               "distort " + dir.string() + " -0.3 0.1") == 0);
  const fs::path out = th::test::scratch_dir("band_parity_out");
  REQUIRE(th::test::run_python("tests/python/view_reference.py",
                               "view " + dir.string() + " 0 0 0.5 " + out.string()) == 0);
  const auto ref_mask = th::io::read_npy(out / "mask.npy");
  const auto ref_image = th::io::read_npy(out / "image.npy");

  const auto human = ZjuMocapSequence::open(dir);
  ViewOptions o;
  o.ratio = 0.5;
  o.border_band = true;
  const ViewImage view = load_view(*human, 0, 0, o);
  const auto mask =
      torch::from_blob(view.mask.data, {view.mask.rows, view.mask.cols}, torch::kUInt8).clone();
  const auto image =
      torch::from_blob(view.rgb.data, {view.rgb.rows, view.rgb.cols, 3}, torch::kFloat32).clone();
  REQUIRE(mask.sizes() == ref_mask.sizes());
  CHECK(torch::equal(mask, ref_mask));
  CHECK(torch::equal(image, ref_image));
  const auto blended = (mask != 0) & (mask != 1) & (mask != 100);
  CHECK(blended.sum().item<int64_t>() > 0);  // interpolated band and edge values

  // Marking the band after undistortion (the non-default order) gives another mask.
  o.band_before_undistort = false;
  const ViewImage other = load_view(*human, 0, 0, o);
  const auto other_mask =
      torch::from_blob(other.mask.data, {other.mask.rows, other.mask.cols}, torch::kUInt8).clone();
  CHECK_FALSE(torch::equal(other_mask, ref_mask));
}
