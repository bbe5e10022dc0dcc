#include "data/zju_mocap.hpp"

#include <algorithm>
#include <cctype>
#include <cstdio>
#include <fstream>
#include <numeric>
#include <opencv2/calib3d.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <sstream>

#include "core/error.hpp"
#include "core/files.hpp"
#include "geometry/camera.hpp"
#include "io/npy.hpp"

namespace th::data {
namespace fs = std::filesystem;

namespace {

torch::Tensor calib(const io::Value& list, size_t cam, std::vector<int64_t> shape,
                    const std::string& what, const fs::path& file) {
  torch::Tensor t;
  try {
    t = list.at(cam).as_tensor().to(torch::kFloat64);
  } catch (const Error& e) {
    fail("'", file.string(), "': cams['", what, "'][", cam, "]: ", e.what());
  }
  const int64_t n = std::accumulate(shape.begin(), shape.end(), int64_t(1), std::multiplies<>());
  if (t.numel() != n)
    fail("'", file.string(), "': cams['", what, "'][", cam, "] has ", t.numel(),
         " values, expected ", n);
  require_finite(t, file, "cams['" + what + "'][" + std::to_string(cam) + "]");
  return t.reshape(shape).contiguous();
}

torch::Tensor flat_f64(const io::Value& dict, const char* key, int64_t expected,
                       const fs::path& file) {
  const io::Value* v = dict.find(key);
  if (!v) fail("'", file.string(), "' has no '", key, "'");
  torch::Tensor t;
  try {
    t = v->as_tensor().to(torch::kFloat64).reshape({-1});
  } catch (const Error& e) {
    fail("'", file.string(), "': '", key, "': ", e.what());
  }
  if (expected > 0 && t.numel() != expected)
    fail("'", file.string(), "': '", key, "' has ", t.numel(), " values, expected ", expected);
  require_finite(t, file, std::string("'") + key + "'");
  return t;
}

}  // namespace

int frame_number_of(const std::string& filename) {
  const std::string stem = fs::path(filename).stem().string();
  auto parse = [](const std::string& s) -> int {
    if (s.empty() || s.size() > 9 || !std::all_of(s.begin(), s.end(), ::isdigit)) return -1;
    return std::stoi(s);
  };
  if (stem.rfind("CoreView_", 0) == 0) {  // CoreView_313_Camera_(1)_0001_2019-...: field 4
    std::vector<std::string> parts;
    std::stringstream ss(stem);
    for (std::string p; std::getline(ss, p, '_');) parts.push_back(p);
    return parts.size() > 4 ? parse(parts[4]) : -1;
  }
  return parse(stem);
}

std::shared_ptr<ZjuMocapSequence> ZjuMocapSequence::open(const fs::path& dir) {
  if (!fs::is_directory(dir)) fail("human folder '", dir.string(), "' does not exist");
  const fs::path file = dir / "annots.npy";
  refuse_special_file(file, "annotations");
  if (!fs::is_regular_file(file))
    fail("'", file.string(), "' is missing (every human folder needs its annots.npy)");
  const io::Value annots = io::read_npy_value(file);

  std::shared_ptr<ZjuMocapSequence> h(new ZjuMocapSequence(dir.filename().string(), dir));
  try {
    const io::Value& cams = annots["cams"];
    const size_t n = cams["K"].size();
    for (const char* key : {"R", "T", "D"})
      if (cams[key].size() != n)
        fail("cams['", key, "'] has ", cams[key].size(), " entries but cams['K'] has ", n);
    for (size_t c = 0; c < n; ++c) {
      Camera cam;
      cam.K = calib(cams["K"], c, {3, 3}, "K", file);
      cam.R = calib(cams["R"], c, {3, 3}, "R", file);
      cam.T = calib(cams["T"], c, {3, 1}, "T", file) / 1000.0;  // METHOD 2.1: mm -> m
      cam.D = calib(cams["D"], c, {5, 1}, "D", file);
      h->cameras_.push_back(cam);
    }
    for (const auto& frame : annots["ims"].as_list()) {
      std::vector<std::string> paths;
      for (const auto& p : frame["ims"].as_list()) paths.push_back(p.as_str());
      if (paths.size() != n)
        fail("ims[", h->ims_.size(), "] lists ", paths.size(), " images for ", n, " cameras");
      h->ims_.push_back(std::move(paths));
    }
  } catch (const Error& e) {
    const std::string what = e.what();
    if (what.rfind("'" + file.string() + "'", 0) == 0) throw;
    fail("'", file.string(), "': ", what);
  }
  if (h->ims_.empty()) fail("'", file.string(), "' lists no frames");
  for (const auto& image : h->ims_.front()) {
    const std::string folder = fs::path(image).parent_path().string();
    h->camera_names_.push_back(folder.empty() ? std::to_string(h->camera_names_.size()) : folder);
  }
  return h;
}

fs::path ZjuMocapSequence::resolve(const fs::path& relative) const {
  if (auto found = find(relative)) return *found;
  const fs::path direct = dir() / relative, folder = direct.parent_path();
  if (!fs::is_directory(folder))
    fail("folder '", folder.string(), "' is missing (needed for '", relative.string(), "')");
  fail("file '", direct.string(), "' is missing (listed in annots.npy)");
}

std::optional<fs::path> ZjuMocapSequence::find(const fs::path& relative) const {
  const fs::path direct = dir() / relative;
  if (exists_or_fail(direct)) return direct;
  // Renamed or original CoreView_313/315 names: look the frame number up in the folder.
  const fs::path folder = direct.parent_path();
  const int number = frame_number_of(relative.filename().string());
  if (number >= 0 && fs::is_directory(folder)) {
    std::lock_guard<std::mutex> lock(cache_mutex_);
    auto it = folder_index_.find(folder);
    if (it == folder_index_.end()) {
      std::map<int, std::string> index;
      for (const auto& entry : fs::directory_iterator(folder)) {
        const int n = frame_number_of(entry.path().filename().string());
        if (n >= 0) index.emplace(n, entry.path().filename().string());
      }
      it = folder_index_.emplace(folder, std::move(index)).first;
    }
    auto hit = it->second.find(number);
    if (hit != it->second.end() && fs::path(hit->second).extension() == relative.extension())
      return folder / hit->second;
  }
  return std::nullopt;
}

fs::path ZjuMocapSequence::image_path(int frame, int cam) const {
  if (frame < 0 || frame >= num_frames())
    fail(name(), ": frame ", frame, " does not exist (annots lists ", num_frames(), ")");
  camera(cam);
  return resolve(ims_[frame][cam]);
}

int ZjuMocapSequence::frame_number(int frame) const {
  const std::string& image = ims_.at(size_t(frame)).at(0);
  const int n = frame_number_of(fs::path(image).filename().string());
  if (n < 0) fail(name(), ": cannot read a frame number from image name '", image, "'");
  return n;
}

fs::path ZjuMocapSequence::body_file(const char* kind, const char* legacy, int frame) const {
  const std::string file = std::to_string(frame_number(frame)) + ".npy";
  const fs::path modern = dir() / kind / file, old = dir() / legacy / file;
  if (fs::exists(modern)) return modern;
  if (fs::exists(old)) return old;
  fail("'", modern.string(), "' is missing (nor is there '", old.string(), "')");
}

BodyParams ZjuMocapSequence::load_params(int frame) const {
  const fs::path file = body_file("new_params", "params", frame);
  const io::Value dict = io::read_npy_value(file);
  if (dict.kind() != io::Value::Kind::Dict)
    fail("'", file.string(), "' must hold a dict, not ", dict.type_name());
  return {flat_f64(dict, "poses", 72, file), flat_f64(dict, "Rh", 3, file),
          flat_f64(dict, "Th", 3, file), flat_f64(dict, "shapes", 0, file)};
}

torch::Tensor ZjuMocapSequence::load_vertices(int frame) const {
  const fs::path file = body_file("new_vertices", "vertices", frame);
  const torch::Tensor v = io::read_npy(file);
  if (v.dim() != 2 || v.size(1) != 3)
    fail("'", file.string(), "' must hold an (N, 3) array, not ", v.sizes());
  require_finite(v, file, "the vertices");
  return v.to(torch::kFloat64);
}

std::vector<fs::path> ZjuMocapSequence::mask_files(int frame, int cam) const {
  image_path(frame, cam);  // checks the indices
  fs::path rel = ims_[frame][cam];
  rel.replace_extension(".png");
  std::vector<std::string> tried;
  std::vector<fs::path> found;
  for (const char* folder : {"mask", "mask_cihp"}) {
    tried.push_back((dir() / folder / rel).string());
    if (const auto p = find(folder / rel)) found.push_back(*p);
  }
  if (found.empty())
    fail("no mask for '", ims_[frame][cam], "': neither '", tried[0], "' nor '", tried[1],
         "' exists");
  return found;
}

fs::path visibility_file(const fs::path& root, const HumanSequence& human, int frame, int cam) {
  const fs::path image = fs::relative(human.image_path(frame, cam), human.dir());
  const std::string stem = image.stem().string();
  const int number = frame_number_of(image.filename().string());
  if (number < 0)
    fail(human.name(), ": cannot read a frame number from image name '", image.string(), "'");
  const bool digits = !stem.empty() && std::all_of(stem.begin(), stem.end(),
                                                   [](unsigned char c) { return std::isdigit(c); });
  const int width = digits ? int(stem.size()) : 4;
  char name[32];
  std::snprintf(name, sizeof name, "%0*d.npy", width, number);
  return root / human.name() / "visibility" / image.parent_path() / name;
}

}  // namespace th::data
