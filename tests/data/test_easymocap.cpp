#include <catch2/catch.hpp>
#include <fstream>
#include <functional>
#include <opencv2/core/persistence.hpp>
#include <opencv2/imgcodecs.hpp>
#include <regex>
#include <sstream>

#include "body/smpl.hpp"
#include "core/error.hpp"
#include "data/dataset.hpp"
#include "data/easymocap.hpp"
#include "data/zju_mocap.hpp"
#include "support/test_env.hpp"

namespace fs = std::filesystem;
using namespace th::data;

namespace {

std::shared_ptr<const th::body::SmplModel> body_model() {
  static auto model = std::make_shared<const th::body::SmplModel>(
      th::body::load_smpl(th::test::tiny_easymocap_dataset() / "smpl_model.npz"));
  return model;
}

OpenOptions options(int person_id = -1, th::CalibrationCheck check = th::CalibrationCheck::error) {
  return {th::DataLayout::easymocap, person_id, body_model(), check};
}

// A private copy of one person of the EasyMocap-layout tiny dataset that a test may damage.
fs::path capture_copy(const std::string& name, const std::string& person = "CoreView_s03") {
  const fs::path dst = th::test::scratch_dir(name) / person;
  fs::copy(th::test::tiny_easymocap_dataset() / person, dst, fs::copy_options::recursive);
  return dst;
}

std::string read_text(const fs::path& file) {
  std::ifstream in(file, std::ios::binary);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

void write_text(const fs::path& file, const std::string& text) {
  std::ofstream(file, std::ios::binary) << text;
}

// Rewrites an intri.yml/extri.yml through OpenCV after `edit` changed its names or matrices.
using Entries = std::vector<std::pair<std::string, cv::Mat>>;
void rewrite(const fs::path& file,
             const std::function<void(std::vector<std::string>&, Entries&)>& edit) {
  std::vector<std::string> names;
  Entries entries;
  {
    cv::FileStorage in(file.string(), cv::FileStorage::READ);
    for (const auto& n : in["names"]) names.push_back(n.string());
    for (const auto& key : in.root().keys()) {
      if (key == "names") continue;
      cv::Mat m;
      in[key] >> m;
      entries.emplace_back(key, m);
    }
  }
  edit(names, entries);
  cv::FileStorage out(file.string(), cv::FileStorage::WRITE);
  if (!names.empty()) out << "names" << names;
  for (const auto& [key, m] : entries) out << key << m;
}

cv::Mat& entry(Entries& entries, const std::string& key) {
  for (auto& [k, m] : entries)
    if (k == key) return m;
  FAIL("no entry " << key);
  return entries.front().second;
}

void erase(Entries& entries, const std::string& key) {
  entries.erase(
      std::remove_if(entries.begin(), entries.end(), [&](const auto& e) { return e.first == key; }),
      entries.end());
}

th::DataConfig capture_config(const fs::path& root) {
  th::DataConfig c;
  c.dataset = th::DatasetKind::capture;
  c.root = root.string();
  c.split_file = "";
  c.smpl_model = (th::test::tiny_easymocap_dataset() / "smpl_model.npz").string();
  c.workers = 0;
  return c;
}

}  // namespace

TEST_CASE("EasyMocap's layout reads the same cameras, bodies, masks and images as ZJU-MoCap's",
          "[easymocap]") {
  for (const char* person : {"CoreView_s03", "CoreView_313"}) {
    INFO(person);
    const auto zju = ZjuMocapSequence::open(th::test::tiny_dataset() / person);
    const auto em = open_human(th::test::tiny_easymocap_dataset() / person,
                               {th::DataLayout::automatic, -1, body_model()});
    REQUIRE(std::string(em->layout()) == "easymocap");
    REQUIRE(em->num_cameras() == zju->num_cameras());
    REQUIRE(em->num_frames() == zju->num_frames());
    CHECK(em->camera_name(0) == "00");
    CHECK(em->calibration_file() == th::test::tiny_easymocap_dataset() / person / "extri.yml");
    for (int c = 0; c < em->num_cameras(); ++c) {
      CHECK(torch::equal(em->camera(c).K, zju->camera(c).K));
      CHECK(torch::equal(em->camera(c).R, zju->camera(c).R));
      CHECK(torch::equal(em->camera(c).T, zju->camera(c).T));
      CHECK(torch::equal(em->camera(c).D, zju->camera(c).D));
    }
    for (int f = 0; f < em->num_frames(); ++f) {
      const auto a = zju->load_params(f), b = em->load_params(f);
      CHECK(torch::equal(a.poses, b.poses));
      CHECK(torch::equal(a.Rh, b.Rh));
      CHECK(torch::equal(a.Th, b.Th));
      CHECK(torch::equal(a.shapes, b.shapes));
      CHECK(torch::equal(zju->load_vertices(f), em->load_vertices(f)));
      for (int c : {0, 7, em->num_cameras() - 1}) {
        CHECK(read_text(zju->image_path(f, c)) == read_text(em->image_path(f, c)));
        CHECK(cv::countNonZero(zju->load_mask(f, c) != em->load_mask(f, c)) == 0);
      }
    }
  }
}

TEST_CASE("the layout of a person's folder is detected and named in the log", "[easymocap]") {
  CHECK(detect_layout(th::test::tiny_dataset() / "CoreView_s03") == th::DataLayout::zju_mocap);
  CHECK(detect_layout(th::test::tiny_easymocap_dataset() / "CoreView_s03") ==
        th::DataLayout::easymocap);
  const fs::path both = capture_copy("easymocap_both");
  fs::copy_file(th::test::tiny_dataset() / "CoreView_s03" / "annots.npy", both / "annots.npy");
  CHECK_THROWS_WITH(detect_layout(both),
                    Catch::Contains("holds both annots.npy") && Catch::Contains("data.layout"));
  const fs::path empty = th::test::scratch_dir("easymocap_neither");
  CHECK_THROWS_WITH(detect_layout(empty),
                    Catch::Contains("holds neither annots.npy") && Catch::Contains("intri.yml"));
}

TEST_CASE("each malformed EasyMocap file is refused naming the file and key", "[easymocap]") {
  struct Case {
    std::string name;
    std::function<void(const fs::path&)> damage;
    std::string message;
  };
  const std::vector<Case> cases{
      {"intri.yml missing", [](const fs::path& d) { fs::remove(d / "intri.yml"); },
       "intri.yml' is missing"},
      {"intri.yml empty", [](const fs::path& d) { write_text(d / "intri.yml", "\n"); },
       "intri.yml' is empty"},
      {"intri.yml not YAML",
       [](const fs::path& d) { write_text(d / "intri.yml", "{{{ not: yaml"); },
       "cannot be read as OpenCV FileStorage YAML"},
      {"no names",
       [](const fs::path& d) { rewrite(d / "intri.yml", [](auto& n, auto&) { n.clear(); }); },
       "intri.yml' has no 'names' list"},
      {"a name twice",
       [](const fs::path& d) { rewrite(d / "intri.yml", [](auto& n, auto&) { n[1] = n[0]; }); },
       "camera '00' is listed twice"},
      {"K missing",
       [](const fs::path& d) {
         rewrite(d / "intri.yml", [](auto&, auto& e) { erase(e, "K_05"); });
       },
       "intri.yml' has no 'K_05'"},
      {"K 2x3",
       [](const fs::path& d) {
         rewrite(d / "intri.yml", [](auto&, auto& e) {
           entry(e, "K_05") = entry(e, "K_05").rowRange(0, 2).clone();
         });
       },
       "'K_05' is 2x3, expected 3x3"},
      {"dist 1x3",
       [](const fs::path& d) {
         rewrite(d / "intri.yml", [](auto&, auto& e) {
           entry(e, "dist_05") = entry(e, "dist_05").colRange(0, 3).clone();
         });
       },
       "'dist_05' is 1x3, expected 1x5 or 5x1 or 1x4 or 4x1"},
      {"intri.yml nested 100,000 deep",
       [](const fs::path& d) {
         write_text(d / "intri.yml", read_text(d / "intri.yml") +
                                         "junk: " + std::string(100000, '[') +
                                         std::string(100000, ']') + "\n");
       },
       "intri.yml' nests 100000 levels deep, more than a calibration file may (64"},
      {"extri.yml of 2 MiB", [](const fs::path& d) { fs::resize_file(d / "extri.yml", 2 << 20); },
       "extri.yml' is 2097152 bytes, more than a calibration file may be (1048576)"},
      {"a camera only in extri.yml",
       [](const fs::path& d) { rewrite(d / "extri.yml", [](auto& n, auto&) { n.back() = "99"; }); },
       "list different cameras in 'names': '99' is only in '"},
      {"NaN in K",
       [](const fs::path& d) {
         rewrite(d / "intri.yml",
                 [](auto&, auto& e) { entry(e, "K_05").template at<double>(0, 0) = std::nan(""); });
       },
       "nan at index 0 (1 non-finite value)"},
      {"no rotation",
       [](const fs::path& d) {
         rewrite(d / "extri.yml", [](auto&, auto& e) { erase(e, "R_05"), erase(e, "Rot_05"); });
       },
       "has neither 'Rot_05' nor 'R_05'"},
      {"R against Rot",
       [](const fs::path& d) {
         rewrite(d / "extri.yml",
                 [](auto&, auto& e) { entry(e, "R_05").template at<double>(0, 0) += 0.1; });
       },
       "'R_05' (Rodrigues) and 'Rot_05' disagree by"},
      {"T missing",
       [](const fs::path& d) {
         rewrite(d / "extri.yml", [](auto&, auto& e) { erase(e, "T_05"); });
       },
       "extri.yml' has no 'T_05'"},
      {"camera folder missing", [](const fs::path& d) { fs::remove_all(d / "images" / "05"); },
       "images/05' is missing"},
      {"a frame missing in one camera",
       [](const fs::path& d) { fs::remove(d / "images" / "05" / "000002.jpg"); },
       "images/05/000002.jpg' is missing: camera '00' has frame 2 but camera '05' has not"},
      {"an image not named by frame",
       [](const fs::path& d) {
         fs::copy_file(d / "images" / "05" / "000002.jpg", d / "images" / "05" / "frame_b.jpg");
       },
       "are named by frame number"},
  };
  for (const auto& c : cases) {
    INFO(c.name);
    const fs::path dir = capture_copy("easymocap_broken");
    c.damage(dir);
    CHECK_THROWS_WITH(EasyMocapSequence::open(dir, options()), Catch::Contains(c.message));
  }
  // calibration_check: warn goes on with Rot.
  const fs::path dir = capture_copy("easymocap_rot_warn");
  rewrite(dir / "extri.yml",
          [](auto&, auto& e) { entry(e, "R_05").template at<double>(0, 0) += 0.1; });
  const auto warned = EasyMocapSequence::open(dir, options(-1, th::CalibrationCheck::warn));
  const auto clean =
      EasyMocapSequence::open(th::test::tiny_easymocap_dataset() / "CoreView_s03", options());
  CHECK(torch::equal(warned->camera(5).R, clean->camera(5).R));
  // Either rotation form alone, and a 5x1 distortion.
  const fs::path alone = capture_copy("easymocap_rodrigues_only");
  rewrite(alone / "extri.yml", [](auto&, auto& e) { erase(e, "Rot_05"); });
  rewrite(alone / "intri.yml",
          [](auto&, auto& e) { entry(e, "dist_05") = entry(e, "dist_05").t(); });
  const auto rodrigues_only = EasyMocapSequence::open(alone, options());
  CHECK(torch::allclose(rodrigues_only->camera(5).R, clean->camera(5).R, 0, 1e-12));
  CHECK(torch::equal(rodrigues_only->camera(5).D, clean->camera(5).D));

  // As EasyMocap writes them too: four distortion coefficients (k3 = 0), cameras named by bare
  // numbers, extri.yml's cameras in another order.
  const fs::path variants = capture_copy("easymocap_variants");
  rewrite(variants / "intri.yml",
          [](auto&, auto& e) { entry(e, "dist_05") = entry(e, "dist_05").colRange(0, 4).clone(); });
  rewrite(variants / "extri.yml", [](auto& n, auto&) { std::reverse(n.begin(), n.end()); });
  const auto read = EasyMocapSequence::open(variants, options());
  CHECK(torch::equal(read->camera(5).D.slice(0, 0, 4), clean->camera(5).D.slice(0, 0, 4)));
  CHECK(read->camera(5).D[4].item<double>() == 0.0);
  CHECK(torch::equal(read->camera(7).R, clean->camera(7).R));
  CHECK(read->camera_name(0) == "00");
  // Cameras named 0..22, the names written as bare numbers (- 5), keys and folders to match.
  const fs::path numbered = capture_copy("easymocap_numbered");
  for (const char* file : {"intri.yml", "extri.yml"})
    write_text(numbered / file,
               std::regex_replace(std::regex_replace(read_text(numbered / file),
                                                     std::regex("- \"0?([0-9]+)\""), "- $1"),
                                  std::regex("_0([0-9]):"), "_$1:"));
  for (const char* folder : {"images", "mask"})
    for (int c = 0; c < 10; ++c)
      fs::rename(numbered / folder / ("0" + std::to_string(c)),
                 numbered / folder / std::to_string(c));
  REQUIRE_THAT(read_text(numbered / "intri.yml"), Catch::Contains("- 5\n"));
  const auto named = EasyMocapSequence::open(numbered, options());
  CHECK(named->camera_name(5) == "5");
  CHECK(named->camera_name(12) == "12");
  CHECK(torch::equal(named->camera(5).K, clean->camera(5).K));
}

TEST_CASE("EasyMocap's SMPL files and masks are checked when a frame is read", "[easymocap]") {
  const auto damaged = [](const std::string& what,
                          const std::function<void(const fs::path&)>& damage) {
    const fs::path dir = capture_copy("easymocap_frame_" + what);
    damage(dir);
    return dir;
  };
  const fs::path smpl1 = fs::path("output") / "smpl" / "000001.json";
  const auto open = [](const fs::path& dir, int id = -1) {
    return EasyMocapSequence::open(dir, options(id));
  };

  auto dir = damaged("missing", [&](const fs::path& d) { fs::remove(d / smpl1); });
  CHECK_THROWS_WITH(open(dir)->load_params(1),
                    Catch::Contains("output/smpl/000001.json' is missing") &&
                        Catch::Contains("smpl/000001.json"));
  CHECK_NOTHROW(open(dir)->load_params(0));

  dir = damaged("json", [&](const fs::path& d) {
    write_text(d / smpl1, "[{\"id\": 0, \"Rh\": [[NaN, 0, 0]]}]");
  });
  CHECK_THROWS_WITH(open(dir)->load_params(1), Catch::Contains("000001.json' is not valid JSON"));

  dir = damaged("empty", [&](const fs::path& d) { write_text(d / smpl1, "[]"); });
  CHECK_THROWS_WITH(open(dir)->load_params(1), Catch::Contains("lists no person"));

  // Two people: the only one is no longer clear; data.person_id picks one.
  const auto two = [&](const fs::path& d) {
    std::string one = read_text(d / smpl1);
    one = one.substr(1, one.rfind(']') - 1);  // the person object
    std::string other = one;
    other.replace(other.find("\"id\":0"), 6, "\"id\":3");
    write_text(d / smpl1, "[" + one + "," + other + "]");
  };
  dir = damaged("two", two);
  CHECK_THROWS_WITH(open(dir)->load_params(1),
                    Catch::Contains("holds 2 people (ids 0, 3): set data.person_id"));
  CHECK(torch::equal(open(dir, 3)->load_params(1).poses, open(dir, 0)->load_params(1).poses));
  CHECK_THROWS_WITH(open(dir, 7)->load_params(1),
                    Catch::Contains("no person with id 7 (data.person_id; ids: 0, 3)"));

  dir = damaged("poses", [&](const fs::path& d) {
    std::string t = read_text(d / smpl1);
    const size_t at = t.find("\"poses\":[[") + 10;
    t.erase(at, t.find(',', t.find(',', t.find(',', at) + 1) + 1) + 1 - at);  // drop three values
    write_text(d / smpl1, t);
  });
  CHECK_THROWS_WITH(open(dir)->load_params(1),
                    Catch::Contains("person id 0's 'poses' has 69 values, expected 72"));

  dir = damaged("text", [&](const fs::path& d) {
    std::string t = read_text(d / smpl1);
    t.replace(t.find("\"Th\":[["), 7, "\"Th\":[[\"x\",");
    write_text(d / smpl1, t);
  });
  CHECK_THROWS_WITH(open(dir)->load_params(1),
                    Catch::Contains("person id 0's 'Th' holds string where numbers belong"));

  dir = damaged("shapes", [&](const fs::path& d) {
    std::string t = read_text(d / smpl1);
    const size_t at = t.find("\"shapes\":[[") + 11;
    std::string zeros;
    for (int i = 0; i < 300; ++i) zeros += "0,";
    t.insert(at, zeros);
    write_text(d / smpl1, t);
  });
  CHECK_THROWS_WITH(open(dir)->load_params(1),
                    Catch::Contains("shape directions (is data.smpl_model the model"));

  dir = damaged("mask", [&](const fs::path& d) { fs::remove(d / "mask" / "05" / "000001.png"); });
  CHECK_THROWS_WITH(open(dir)->load_mask(1, 5), Catch::Contains("no mask for") &&
                                                    Catch::Contains("mask/05/000001.png") &&
                                                    Catch::Contains("masks/05/000001.png"));
  // masks/ (the other spelling) is read as well.
  fs::create_directories(dir / "masks" / "05");
  fs::copy_file(th::test::tiny_easymocap_dataset() / "CoreView_s03" / "mask" / "05" / "000001.png",
                dir / "masks" / "05" / "000001.png");
  CHECK(cv::countNonZero(open(dir)->load_mask(1, 5)) > 0);

  // Masks at any depth, or as an alpha-only cut-out, read as the 8-bit mask reads.
  const fs::path mask05 = fs::path("mask") / "05" / "000001.png";
  const cv::Mat eight = open(capture_copy("easymocap_mask8"))->load_mask(1, 5);
  REQUIRE(cv::countNonZero(eight) > 0);
  for (const std::string kind : {"u16_255", "u16_1", "rgba", "colour"}) {
    INFO(kind);
    dir = damaged("mask_" + kind, [&](const fs::path& d) {
      cv::Mat m = eight.clone(), out;
      if (kind == "u16_255") m.convertTo(out, CV_16U, 255);
      if (kind == "u16_1") m.convertTo(out, CV_16U);
      if (kind == "rgba") {
        const cv::Mat zero = cv::Mat::zeros(m.size(), CV_8U);
        cv::merge(std::vector<cv::Mat>{zero, zero, zero, m * 255}, out);
      }
      if (kind == "colour") {
        const cv::Mat zero = cv::Mat::zeros(m.size(), CV_8U);
        cv::merge(std::vector<cv::Mat>{zero, m * 7, zero}, out);
      }
      cv::imwrite((d / mask05).string(), out);
    });
    CHECK(cv::countNonZero(open(dir)->load_mask(1, 5) != eight) == 0);
  }
  // An opaque RGBA mask: its colours mark the person.
  dir = damaged("mask_opaque", [&](const fs::path& d) {
    cv::Mat out, grey = eight * 255;
    cv::merge(std::vector<cv::Mat>{grey, grey, grey, cv::Mat(grey.size(), CV_8U, 255)}, out);
    cv::imwrite((d / mask05).string(), out);
  });
  CHECK(cv::countNonZero(open(dir)->load_mask(1, 5) != eight) == 0);

  // Nesting and size bounded before the values are walked; ids distinct.
  dir = damaged("deep", [&](const fs::path& d) {
    std::string t = read_text(d / smpl1);
    t.insert(t.find("\"poses\":[") + 9, std::string(100000, '[') + std::string(100000, ']') + ",");
    write_text(d / smpl1, t);
  });
  CHECK_THROWS_WITH(open(dir)->load_params(1),
                    Catch::Contains("key 'poses' nests more than 8 levels deep"));
  dir = damaged("large", [&](const fs::path& d) { fs::resize_file(d / smpl1, 9 << 20); });
  CHECK_THROWS_WITH(open(dir)->load_params(1),
                    Catch::Contains("more than an SMPL fit file may be (8388608)"));
  dir = damaged("same_ids", [&](const fs::path& d) {
    std::string one = read_text(d / smpl1);
    one = one.substr(1, one.rfind(']') - 1);
    write_text(d / smpl1, "[" + one + "," + one + "]");
  });
  CHECK_THROWS_WITH(open(dir, 0)->load_params(1),
                    Catch::Contains("people [0] and [1] have the same id 0"));
  // A link loop is named as such, not "missing".
  dir = damaged("loop", [&](const fs::path& d) {
    fs::remove(d / smpl1);
    fs::create_symlink("000001.json", d / smpl1);
  });
  CHECK_THROWS_WITH(open(dir)->load_params(1),
                    Catch::Contains("Too many levels of symbolic links"));

  dir = damaged("mask_size", [&](const fs::path& d) {
    cv::imwrite((d / "mask" / "05" / "000001.png").string(), cv::Mat::zeros(10, 12, CV_8U));
  });
  CHECK_THROWS_WITH(load_view(*open(dir), 1, 5, {}),
                    Catch::Contains("mask of '") && Catch::Contains("is 12x10"));

  dir = damaged("jpeg", [&](const fs::path& d) {
    const fs::path image = d / "images" / "05" / "000001.jpg";
    const std::string bytes = read_text(image);
    write_text(image, bytes.substr(0, bytes.size() / 2));
  });
  CHECK_THROWS_WITH(load_view(*open(dir), 1, 5, {}), Catch::Contains("000001.jpg' is truncated"));
}

TEST_CASE("cameras are chosen by name or index, quoted split entries being names", "[easymocap]") {
  const auto em =
      EasyMocapSequence::open(th::test::tiny_easymocap_dataset() / "CoreView_s03", options());
  CHECK(camera_index(*em, "07", "here") == 7);  // the name "07"
  CHECK(camera_index(*em, "7", "here") == 7);   // index 7, also called "07"
  CHECK_THROWS_WITH(camera_index(*em, "A1", "here"),
                    Catch::Contains("here: CoreView_s03 has no camera 'A1' (its cameras: 00, 01"));
  CHECK_THROWS_WITH(camera_index(*em, "40", "here"),
                    Catch::Contains("camera 40 does not exist for CoreView_s03 (23 cameras"));
  // Names 1-based, as many rigs count: "15" names camera 14 and indexes camera 15.
  const fs::path dir = capture_copy("easymocap_one_based");
  for (const char* file : {"intri.yml", "extri.yml"}) {
    std::string text = read_text(dir / file);
    for (int c = 22; c >= 0; --c) {
      char from[8], to[8];
      std::snprintf(from, sizeof from, "%02d", c);
      std::snprintf(to, sizeof to, "%02d", c + 1);
      for (const std::string prefix : {"\"", "K_", "dist_", "R_", "Rot_", "T_"}) {
        size_t at = 0;
        while ((at = text.find(prefix + from + (prefix == "\"" ? "\"" : ":"), at)) !=
               std::string::npos) {
          text.replace(at + prefix.size(), 2, to);
          at += prefix.size() + 2;
        }
      }
    }
    write_text(dir / file, text);
  }
  for (int c = 22; c >= 0; --c) {
    char from[8], to[8];
    std::snprintf(from, sizeof from, "%02d", c);
    std::snprintf(to, sizeof to, "%02d", c + 1);
    fs::rename(dir / "images" / from, dir / "images" / to);
    fs::rename(dir / "mask" / from, dir / "mask" / to);
  }
  const auto one_based = EasyMocapSequence::open(dir, options());
  CHECK(one_based->camera_name(0) == "01");
  CHECK(camera_index(*one_based, "01", "here") == 0);  // names first
  CHECK(camera_index(*one_based, "15", "here") == 14);
  CHECK(camera_index(*one_based, "15", "here", /*index_only=*/true) == 15);
  CHECK(camera_index(*one_based, "0", "here") == 0);  // no camera "0": index 0
  // In a split file a quoted entry is a name and a plain number an index.
  const fs::path split = dir.parent_path() / "split.yaml";
  write_text(
      split,
      "settings:\n  s:\n    reference_views: [\"01\", \"08\", 15]\n    target_views: [cam_a]\n"
      "    humans: [{name: CoreView_s03, begin: 0, ni: 1, interval: 1}]\n");
  const auto s = load_split(split, "s");
  CHECK(s.reference_views == std::vector<CameraRef>{{"01", false}, {"08", false}, {"15", true}});
  CHECK(s.target_views == std::vector<CameraRef>{{"cam_a", false}});
  std::vector<int> picked;
  for (const auto& v : s.reference_views)
    picked.push_back(camera_index(*one_based, v.text, "split", v.index));
  CHECK(picked == std::vector<int>{0, 7, 15});
}

TEST_CASE("a capture without a split file uses every frame and the most spread reference cameras",
          "[easymocap]") {
  const fs::path root = th::test::scratch_dir("easymocap_no_split");
  fs::copy(th::test::tiny_easymocap_dataset() / "CoreView_s03", root / "CoreView_s03",
           fs::copy_options::recursive);
  auto c = capture_config(root);
  const Dataset test(c, "identity", Dataset::Mode::Test, body_model());
  REQUIRE(test.humans().size() == 1);
  const auto& human = *test.humans()[0];
  const auto refs = test.reference_views(0);
  REQUIRE(refs.size() == 3);
  CHECK(refs == spread_cameras(human, human.load_vertices(0), 3));
  CHECK(test.size() == size_t(human.num_frames() * (human.num_cameras() - 3)));
  for (size_t i = 0; i < test.size(); ++i)
    CHECK(std::find(refs.begin(), refs.end(), test.item(i).target_view) == refs.end());
  CHECK(test.load(0, 1).reference_views == refs);

  // Training: every camera of every frame, references drawn per sample.
  const Dataset train(c, "training", Dataset::Mode::Train, body_model());
  CHECK(train.size() == size_t(human.num_frames() * human.num_cameras()));
  CHECK(train.reference_views(0).empty());

  // data.reference_views, by name.
  c.reference_views = {"04", "12", "19"};
  const Dataset chosen(c, "identity", Dataset::Mode::Test, body_model());
  CHECK(chosen.reference_views(0) == std::vector<int>{4, 12, 19});
  CHECK(chosen.size() == size_t(human.num_frames() * (human.num_cameras() - 3)));
  c.reference_views = {"04", "side"};
  CHECK_THROWS_WITH(Dataset(c, "identity", Dataset::Mode::Test, body_model()),
                    Catch::Contains("data.reference_views: CoreView_s03 has no camera 'side'"));

  // An empty data.root is named.
  c.root = th::test::scratch_dir("easymocap_empty_root").string();
  CHECK_THROWS_WITH(
      Dataset(c, "identity", Dataset::Mode::Test, body_model()),
      Catch::Contains("holds no person's folder") && Catch::Contains("data.split_file is empty"));
}

TEST_CASE("the most evenly spread cameras of a ring split it into near-equal arcs", "[easymocap]") {
  const auto em =
      EasyMocapSequence::open(th::test::tiny_easymocap_dataset() / "CoreView_s03", options());
  const auto body = em->load_vertices(0);
  CHECK(spread_cameras(*em, body, 1) == std::vector<int>{0});
  const auto four = spread_cameras(*em, body, 4);
  REQUIRE(four.size() == 4);
  CHECK(std::is_sorted(four.begin(), four.end()));
  // 23 cameras in a ring: four picks leave gaps of 5 or 6 cameras.
  for (size_t i = 0; i + 1 < four.size(); ++i)
    CHECK((four[i + 1] - four[i] == 5 || four[i + 1] - four[i] == 6));
  CHECK_THROWS_WITH(spread_cameras(*em, body, 24),
                    Catch::Contains("24 reference views asked for but it has 23 cameras"));
}
