#include "data/easymocap.hpp"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <cctype>
#include <fstream>
#include <nlohmann/json.hpp>
#include <opencv2/calib3d.hpp>
#include <opencv2/core/persistence.hpp>
#include <opencv2/imgcodecs.hpp>

#include "body/smpl.hpp"
#include "core/error.hpp"
#include "core/files.hpp"
#include "data/zju_mocap.hpp"
#include "geometry/camera.hpp"

namespace th::data {
namespace fs = std::filesystem;

namespace {

// Tolerance between a camera's two rotation forms (Rodrigues R_<c> against Rot_<c>).
constexpr double kRotationAgreement = 1e-4;

// Bounds on a calibration file, checked before OpenCV parses it: its YAML, JSON and XML parsers
// recurse once per level of nesting, so a deeply nested file would overflow the stack.
// EasyMocap's files nest two levels and hold a few hundred values per camera.
constexpr uintmax_t kMaxCalibrationBytes = uintmax_t{1} << 20;
constexpr int kMaxCalibrationDepth = 64;

// The deepest nesting `text` could hold, counted without parsing: flow brackets ([ {) and XML
// elements outside quotes, and on each line the columns before its first value (a block level
// takes at least one column, "- " two).
int nesting_bound(const std::string& text) {
  int deepest = 0, flow = 0, xml = 0;
  char quote = 0;
  bool line_start = true;
  int indent = 0;
  for (size_t i = 0; i < text.size(); ++i) {
    const char c = text[i];
    if (c == '\n') {
      line_start = true, indent = 0;
      continue;
    }
    if (line_start) {
      if (c == ' ' || c == '\t' || (c == '-' && i + 1 < text.size() && text[i + 1] == ' ')) {
        deepest = std::max(deepest, ++indent);
        continue;
      }
      line_start = false;
    }
    if (quote) {
      if (c == quote) quote = 0;
      continue;
    }
    if (c == '"' || c == '\'') {
      quote = c;
    } else if (c == '#' && (i == 0 || text[i - 1] == ' ')) {
      while (i + 1 < text.size() && text[i + 1] != '\n') ++i;  // a comment
    } else if (c == '[' || c == '{') {
      deepest = std::max(deepest, ++flow + indent);
    } else if ((c == ']' || c == '}') && flow > 0) {
      --flow;
    } else if (c == '<' && i + 1 < text.size()) {
      const char next = text[i + 1];
      if (next == '/') {
        xml = std::max(0, xml - 1);
      } else if (next != '?' && next != '!') {
        const size_t end = text.find('>', i);
        if (end == std::string::npos || text[end - 1] != '/') deepest = std::max(deepest, ++xml);
      }
    }
  }
  return deepest;
}

cv::FileStorage open_storage(const fs::path& file) {
  refuse_special_file(file, "calibration");
  if (!exists_or_fail(file))
    fail("'", file.string(), "' is missing (EasyMocap's layout needs intri.yml and extri.yml)");
  std::error_code ec;
  const uintmax_t bytes = fs::file_size(file, ec);
  if (!ec && bytes > kMaxCalibrationBytes)
    fail("'", file.string(), "' is ", bytes, " bytes, more than a calibration file may be (",
         kMaxCalibrationBytes, ")");
  std::ifstream in(file, std::ios::binary);
  const std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  if (text.find_first_not_of(" \t\r\n") == std::string::npos)
    fail("'", file.string(), "' is empty (EasyMocap's calibration is OpenCV FileStorage YAML)");
  if (const int depth = nesting_bound(text); depth > kMaxCalibrationDepth)
    fail("'", file.string(), "' nests ", depth, " levels deep, more than a calibration file may (",
         kMaxCalibrationDepth, "; EasyMocap writes 2)");
  cv::FileStorage storage;
  try {
    storage.open(text, cv::FileStorage::READ | cv::FileStorage::MEMORY);
  } catch (const cv::Exception& e) {
    fail("'", file.string(), "' cannot be read as OpenCV FileStorage YAML: ", e.err);
  }
  if (!storage.isOpened()) fail("'", file.string(), "' cannot be read as OpenCV FileStorage YAML");
  return storage;
}

std::vector<std::string> read_names(const cv::FileStorage& storage, const fs::path& file) {
  const cv::FileNode node = storage["names"];
  if (node.empty() || !node.isSeq())
    fail("'", file.string(), "' has no 'names' list of camera names");
  std::vector<std::string> names;
  for (const auto& item : node) {
    // EasyMocap's writer quotes names; a list written by hand may hold bare numbers (- 1).
    if (!item.isString() && !item.isInt())
      fail("'", file.string(), "': names[", names.size(), "] is neither a string nor an integer");
    const std::string name = item.isInt() ? std::to_string(int(item)) : item.string();
    if (name.empty() || name == "." || name == ".." ||
        name.find_first_of("/\\") != std::string::npos)
      fail("'", file.string(), "': names[", names.size(), "] = '", name, "' is not a folder name");
    if (std::find(names.begin(), names.end(), name) != names.end())
      fail("'", file.string(), "': camera '", name, "' is listed twice in 'names'");
    names.push_back(name);
  }
  if (names.empty()) fail("'", file.string(), "': 'names' lists no camera");
  return names;
}

// A matrix entry as float64 (rows, cols); `shapes` lists the accepted (rows, cols).
torch::Tensor read_matrix(const cv::FileStorage& storage, const fs::path& file,
                          const std::string& key, std::vector<std::pair<int, int>> shapes) {
  const cv::FileNode node = storage[key];
  if (node.empty()) fail("'", file.string(), "' has no '", key, "'");
  cv::Mat m;
  try {
    node >> m;
  } catch (const cv::Exception& e) {
    fail("'", file.string(), "': '", key, "' is not an OpenCV matrix: ", e.err);
  }
  const bool fits = std::any_of(shapes.begin(), shapes.end(),
                                [&](auto s) { return m.rows == s.first && m.cols == s.second; });
  if (m.empty() || m.channels() != 1 || !fits) {
    std::string want;
    for (auto [r, c] : shapes)
      want += (want.empty() ? "" : " or ") + std::to_string(r) + "x" + std::to_string(c);
    fail("'", file.string(), "': '", key, "' is ", m.rows, "x", m.cols,
         (m.channels() > 1 ? " (multi-channel)" : ""), ", expected ", want);
  }
  cv::Mat m64;
  m.convertTo(m64, CV_64F);
  const torch::Tensor t =
      torch::from_blob(m64.ptr<double>(), {m64.rows, m64.cols}, torch::kFloat64).clone();
  require_finite(t, file, "'" + key + "'");
  return t;
}

bool is_image(const fs::path& p) {
  std::string ext = p.extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(),
                 [](unsigned char c) { return std::tolower(c); });
  return ext == ".jpg" || ext == ".jpeg" || ext == ".png";
}

// A JSON array of numbers, nested to any depth ([[3]] and [3] alike), flattened.
std::vector<double> numbers(const nlohmann::json& value, const fs::path& file,
                            const std::string& where) {
  std::vector<double> out;
  const auto walk = [&](const auto& self, const nlohmann::json& v) -> void {
    if (v.is_array()) {
      for (const auto& item : v) self(self, item);
    } else if (v.is_number()) {
      out.push_back(v.get<double>());
    } else {
      fail("'", file.string(), "': ", where, " holds ", v.type_name(), " where numbers belong");
    }
  };
  walk(walk, value);
  return out;
}

torch::Tensor field(const nlohmann::json& person, const char* key, size_t expected,
                    const fs::path& file, const std::string& who) {
  if (!person.contains(key)) fail("'", file.string(), "': ", who, " has no '", key, "'");
  std::vector<double> v = numbers(person[key], file, who + "'s '" + key + "'");
  if ((expected > 0 && v.size() != expected) || v.empty())
    fail("'", file.string(), "': ", who, "'s '", key, "' has ", v.size(), " values, expected ",
         expected > 0 ? std::to_string(expected) : std::string("at least 1"));
  return torch::tensor(v, torch::kFloat64);
}

// Bounds on an SMPL fit file, checked before its values are walked: EasyMocap writes a list of a
// few people, each a map of arrays of arrays (nesting 4), a few kilobytes a frame.
constexpr uintmax_t kMaxFitBytes = uintmax_t{8} << 20;
constexpr int kMaxFitDepth = 8;

// The people of an SMPL fit file, a list (one person alone may be written as an object).
nlohmann::json read_fit(const fs::path& file) {
  std::error_code ec;
  const uintmax_t bytes = fs::file_size(file, ec);
  if (!ec && bytes > kMaxFitBytes)
    fail("'", file.string(), "' is ", bytes, " bytes, more than an SMPL fit file may be (",
         kMaxFitBytes, ")");
  // Parsed with a callback that stops at the first value nested deeper than kMaxFitDepth, naming
  // the key it lies under (the parser itself keeps its own stack, the walks below recurse).
  std::vector<std::string> keys;
  const auto bound = [&](int depth, nlohmann::json::parse_event_t event, nlohmann::json& value) {
    if (event == nlohmann::json::parse_event_t::key) {
      keys.resize(size_t(depth));
      keys.push_back(value.get<std::string>());
    }
    if (depth > kMaxFitDepth) {
      std::string path;
      for (const auto& k : keys)
        if (!k.empty()) path += (path.empty() ? "" : ".") + k;
      fail("'", file.string(), "': ", path.empty() ? "the list" : "key '" + path + "'",
           " nests more than ", kMaxFitDepth, " levels deep (EasyMocap writes 4)");
    }
    return true;
  };
  nlohmann::json people;
  try {
    std::ifstream in(file);
    people = nlohmann::json::parse(in, bound);
  } catch (const nlohmann::json::exception& e) {
    fail("'", file.string(), "' is not valid JSON: ", e.what());
  }
  if (people.is_object()) {
    nlohmann::json list = nlohmann::json::array();
    list.push_back(std::move(people));
    return list;
  }
  return people;
}

}  // namespace

std::shared_ptr<EasyMocapSequence> EasyMocapSequence::open(const fs::path& dir,
                                                           const OpenOptions& options) {
  std::error_code ec;
  if (!fs::is_directory(dir, ec)) fail("human folder '", dir.string(), "' does not exist");
  if (!options.smpl)
    fail(dir.string(),
         ": EasyMocap's layout needs the body model (data.smpl_model) for its vertices");
  std::shared_ptr<EasyMocapSequence> h(new EasyMocapSequence(dir.filename().string(), dir));
  h->person_id_ = options.person_id;
  h->smpl_ = options.smpl;
  h->read_calibration(options.calibration_check);
  h->list_images();
  return h;
}

void EasyMocapSequence::read_calibration(CalibrationCheck check) {
  const fs::path intri_file = dir() / "intri.yml", extri_file = dir() / "extri.yml";
  const cv::FileStorage intri = open_storage(intri_file), extri = open_storage(extri_file);
  camera_names_ = read_names(intri, intri_file);
  if (!extri["names"].empty()) {  // the same cameras, in any order (intri.yml's order is used)
    const std::vector<std::string> extri_names = read_names(extri, extri_file);
    const auto only_in = [&](const std::vector<std::string>& names,
                             const std::vector<std::string>& other, const fs::path& file) {
      for (const std::string& c : names)
        if (std::find(other.begin(), other.end(), c) == other.end())
          fail("'", extri_file.string(), "' and '", intri_file.string(),
               "' list different cameras in 'names': '", c, "' is only in '", file.string(), "'");
    };
    only_in(extri_names, camera_names_, extri_file);
    only_in(camera_names_, extri_names, intri_file);
  }
  for (const std::string& c : camera_names_) {
    Camera cam;
    cam.K = read_matrix(intri, intri_file, "K_" + c, {{3, 3}});
    // k1, k2, p1, p2[, k3]: EasyMocap writes four coefficients as often as five (k3 = 0).
    const torch::Tensor dist =
        read_matrix(intri, intri_file, "dist_" + c, {{1, 5}, {5, 1}, {1, 4}, {4, 1}}).reshape({-1});
    cam.D = torch::zeros({5, 1}, torch::kFloat64);
    cam.D.reshape({5}).slice(0, 0, dist.numel()).copy_(dist);
    const bool has_rot = !extri["Rot_" + c].empty(), has_r = !extri["R_" + c].empty();
    if (!has_rot && !has_r)
      fail("'", extri_file.string(), "' has neither 'Rot_", c, "' nor 'R_", c, "'");
    if (has_r)
      cam.R = geometry::rodrigues(
          read_matrix(extri, extri_file, "R_" + c, {{3, 1}, {1, 3}}).reshape({3}));
    if (has_rot) {
      const torch::Tensor rot = read_matrix(extri, extri_file, "Rot_" + c, {{3, 3}});
      if (has_r) {
        const double diff = (rot - cam.R).abs().max().item<double>();
        if (diff > kRotationAgreement) {
          const std::string message = "'" + extri_file.string() + "': 'R_" + c +
                                      "' (Rodrigues) and 'Rot_" + c + "' disagree by " +
                                      std::to_string(diff) + " (Rot_" + c + " is used)";
          if (check == CalibrationCheck::error)
            fail(message, " (data.calibration_check: warn to go on anyway)");
          spdlog::warn("{} (data.calibration_check: warn; going on)", message);
        }
      }
      cam.R = rot;  // Rot wins
    }
    cam.T = read_matrix(extri, extri_file, "T_" + c, {{3, 1}, {1, 3}}).reshape({3, 1});
    cameras_.push_back(cam);
  }
}

void EasyMocapSequence::list_images() {
  const fs::path images = dir() / "images";
  std::vector<std::map<int, std::string>> per_camera;
  for (const std::string& c : camera_names_) {
    const fs::path folder = images / c;
    std::error_code ec;
    if (!fs::is_directory(folder, ec))
      fail("folder '", folder.string(), "' is missing (camera '", c, "' of '",
           (dir() / "intri.yml").string(), "')");
    std::map<int, std::string> by_number;
    for (const auto& entry : fs::directory_iterator(folder)) {
      if (!is_image(entry.path())) continue;
      const std::string file = entry.path().filename().string();
      const int number = frame_number_of(file);
      if (number < 0)
        fail("image '", entry.path().string(),
             "': EasyMocap's images are named by frame number (000000.jpg)");
      if (!by_number.emplace(number, file).second)
        fail("'", folder.string(), "' holds two images of frame ", number, ": '", by_number[number],
             "' and '", file, "'");
    }
    if (by_number.empty())
      fail("folder '", folder.string(), "' holds no images (.jpg, .jpeg, .png)");
    per_camera.push_back(std::move(by_number));
  }
  for (const auto& [number, file] : per_camera.front()) {
    Frame f;
    f.number = number;
    f.stem = fs::path(file).stem().string();
    for (size_t c = 0; c < per_camera.size(); ++c) {
      const auto it = per_camera[c].find(number);
      if (it == per_camera[c].end())
        fail("'", (images / camera_names_[c] / file).string(), "' is missing: camera '",
             camera_names_.front(), "' has frame ", number, " but camera '", camera_names_[c],
             "' has not (", per_camera[c].size(), " images against ", per_camera.front().size(),
             ")");
      f.image_names.push_back(it->second);
    }
    frames_.push_back(std::move(f));
  }
  for (size_t c = 1; c < per_camera.size(); ++c)
    for (const auto& [number, file] : per_camera[c])
      if (!per_camera.front().count(number))
        fail("'", (images / camera_names_.front() / file).string(), "' is missing: camera '",
             camera_names_[c], "' has frame ", number, " but camera '", camera_names_.front(),
             "' has not");
}

void EasyMocapSequence::check_frame(int frame) const {
  if (frame < 0 || frame >= num_frames())
    fail(name(), ": frame ", frame, " does not exist (", num_frames(), " frames in '",
         (dir() / "images").string(), "')");
}

fs::path EasyMocapSequence::image_path(int frame, int cam) const {
  check_frame(frame);
  return dir() / "images" / camera_name(cam) / frames_[size_t(frame)].image_names[size_t(cam)];
}

int EasyMocapSequence::frame_number(int frame) const {
  check_frame(frame);
  return frames_[size_t(frame)].number;
}

BodyParams EasyMocapSequence::load_params(int frame) const {
  check_frame(frame);
  const std::string file_name = frames_[size_t(frame)].stem + ".json";
  fs::path file = dir() / "output" / "smpl" / file_name;
  if (!exists_or_fail(file)) file = dir() / "smpl" / file_name;
  if (!exists_or_fail(file))
    fail("'", (dir() / "output" / "smpl" / file_name).string(), "' is missing (nor is there '",
         file.string(), "'): EasyMocap's multi-view SMPL fit of frame ",
         frames_[size_t(frame)].number);
  refuse_special_file(file, "SMPL parameters");
  const nlohmann::json people = read_fit(file);
  if (!people.is_array())
    fail("'", file.string(), "' must hold a list of people, not ", people.type_name());
  if (people.empty())
    fail("'", file.string(), "' lists no person (was the fit of this frame lost?)");
  std::vector<int64_t> ids;
  for (size_t i = 0; i < people.size(); ++i) {
    const auto& p = people[i];
    if (!p.is_object())
      fail("'", file.string(), "': person [", i, "] is ", p.type_name(), ", not an object");
    const int64_t id =
        p.contains("id") && p["id"].is_number_integer() ? p["id"].get<int64_t>() : int64_t(i);
    if (std::find(ids.begin(), ids.end(), id) != ids.end())
      fail("'", file.string(), "': people [", std::find(ids.begin(), ids.end(), id) - ids.begin(),
           "] and [", i, "] have the same id ", id, " (which one data.person_id means is unclear)");
    ids.push_back(id);
  }
  std::string found;
  for (const auto id : ids) found += (found.empty() ? "" : ", ") + std::to_string(id);
  size_t pick = 0;
  if (person_id_ < 0) {
    if (people.size() > 1)
      fail("'", file.string(), "' holds ", people.size(), " people (ids ", found,
           "): set data.person_id to one of them");
  } else {
    const auto it = std::find(ids.begin(), ids.end(), int64_t(person_id_));
    if (it == ids.end())
      fail("'", file.string(), "' has no person with id ", person_id_,
           " (data.person_id; ids: ", found, ")");
    pick = size_t(it - ids.begin());
  }
  const auto& p = people[pick];
  const std::string who = "person id " + std::to_string(ids[pick]);
  BodyParams params{field(p, "poses", body::kNumPoseParams, file, who),
                    field(p, "Rh", 3, file, who), field(p, "Th", 3, file, who),
                    field(p, "shapes", 0, file, who)};
  if (params.shapes.numel() > smpl_->num_betas())
    fail("'", file.string(), "': ", who, "'s 'shapes' has ", params.shapes.numel(),
         " values but the body model has ", smpl_->num_betas(),
         " shape directions (is data.smpl_model the model of this fit?)");
  return params;
}

torch::Tensor EasyMocapSequence::load_vertices(int frame) const {
  const BodyParams p = load_params(frame);
  const auto posed = body::lbs(*smpl_, p.poses, p.shapes);
  return body::smpl_to_world(posed.vertices, p.Rh, p.Th).to(torch::kFloat32).to(torch::kFloat64);
}

std::vector<fs::path> EasyMocapSequence::mask_files(int frame, int cam) const {
  const fs::path image = image_path(frame, cam);
  const std::string file = image.stem().string() + ".png";
  std::vector<fs::path> tried, found;
  for (const char* folder : {"mask", "masks"}) {
    tried.push_back(dir() / folder / camera_name(cam) / file);
    if (exists_or_fail(tried.back())) found.push_back(tried.back());
  }
  if (found.empty())
    fail("no mask for '", image.string(), "': neither '", tried[0].string(), "' nor '",
         tried[1].string(), "' exists (non-zero pixels mark the person; docs/YOUR_CAPTURE.md)");
  return found;
}

}  // namespace th::data
