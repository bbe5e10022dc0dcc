#include "bake/baked_frame.hpp"

#include <cmath>
#include <cstring>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>

#include "core/error.hpp"
#include "core/files.hpp"

namespace th::bake {
namespace fs = std::filesystem;
using Json = nlohmann::json;

namespace {

constexpr char kMagic[8] = {'T', 'H', 'B', 'A', 'K', 'E', 'D', '\n'};
constexpr uint32_t kVersion = 1;
// Largest lattice side and brick side a file may declare (a 4096^3 lattice is 2.7e11 points,
// far beyond any body; the bounds keep a corrupt header from asking for absurd allocations).
constexpr int64_t kMaxCells = 4096;
constexpr int kMaxBrick = 64;

template <class T>
void append(std::string& out, const std::vector<T>& v) {
  out.append(reinterpret_cast<const char*>(v.data()), v.size() * sizeof(T));
}

template <class T>
void take(const std::string& bytes, size_t& at, std::vector<T>& v, size_t count) {
  v.resize(count);
  std::memcpy(v.data(), bytes.data() + at, count * sizeof(T));
  at += count * sizeof(T);
}

}  // namespace

std::array<int64_t, 3> BakedFrame::bricks() const {
  std::array<int64_t, 3> n{};
  for (int a = 0; a < 3; ++a) n[a] = (cells[a] + brick - 1) / brick;
  return n;
}

int64_t BakedFrame::stored_bricks() const {
  const int64_t p = points_per_brick();
  return p > 0 ? int64_t(density.size()) / p : 0;
}

int64_t BakedFrame::bytes() const {
  return int64_t(slot.size() * sizeof(int32_t) + (density.size() + color.size()) * sizeof(float));
}

void write_baked(const BakedFrame& f, const fs::path& path) {
  Json header{{"format", "transhuman baked frame"},
              {"version", kVersion},
              {"little_endian", true},
              {"human", f.human},
              {"frame", f.frame},
              {"checkpoint", f.checkpoint},
              {"reference_views", f.reference_views},
              {"voxel", f.voxel},
              {"origin", f.origin},
              {"cells", f.cells},
              {"brick", f.brick},
              {"box", f.box},
              {"cull_distance", f.cull_distance},
              {"color_dims", kColorDims},
              {"stored_bricks", f.stored_bricks()}};
  const std::string text = header.dump(-1, ' ', false, Json::error_handler_t::replace);
  std::string out(kMagic, sizeof(kMagic));
  const uint32_t version = kVersion, length = uint32_t(text.size());
  out.append(reinterpret_cast<const char*>(&version), 4);
  out.append(reinterpret_cast<const char*>(&length), 4);
  out += text;
  append(out, f.slot);
  append(out, f.density);
  append(out, f.color);
  write_file_atomic(path, out);
}

BakedFrame read_baked(const fs::path& path) {
  const std::string where = "baked frame '" + path.string() + "'";
  std::ifstream in(path, std::ios::binary);
  if (!in) fail(where, ": cannot open it");
  std::stringstream ss;
  ss << in.rdbuf();
  const std::string bytes = ss.str();
  if (bytes.size() < 16 || std::memcmp(bytes.data(), kMagic, sizeof(kMagic)) != 0)
    fail(where,
         ": not a baked frame (no THBAKED header; write one with transhuman-render "
         "--bake-out)");
  uint32_t version = 0, length = 0;
  std::memcpy(&version, bytes.data() + 8, 4);
  std::memcpy(&length, bytes.data() + 12, 4);
  if (version != kVersion)
    fail(where, ": format version ", version, ", this build reads version ", kVersion);
  if (16 + size_t(length) > bytes.size()) fail(where, ": truncated inside its header");
  Json h;
  try {
    h = Json::parse(bytes.substr(16, length));
  } catch (const Json::exception& e) {
    fail(where, ": unreadable header (", e.what(), ")");
  }
  BakedFrame f;
  try {
    if (!h.at("little_endian").get<bool>()) fail(where, ": written big-endian");
    f.human = h.at("human").get<std::string>();
    f.frame = h.at("frame").get<int>();
    f.checkpoint = h.at("checkpoint").get<std::string>();
    f.reference_views = h.at("reference_views").get<std::vector<int>>();
    f.voxel = h.at("voxel").get<double>();
    f.origin = h.at("origin").get<std::array<double, 3>>();
    f.cells = h.at("cells").get<std::array<int64_t, 3>>();
    f.brick = h.at("brick").get<int>();
    f.box = h.at("box").get<std::array<double, 6>>();
    f.cull_distance = h.at("cull_distance").get<double>();
    if (h.at("color_dims").get<int>() != kColorDims)
      fail(where, ": header key 'color_dims' = ", h.at("color_dims").dump(), ", expected ",
           kColorDims);
  } catch (const Json::exception& e) {
    fail(where, ": header: ", e.what());
  }
  if (!(std::isfinite(f.voxel) && f.voxel > 0))
    fail(where, ": header key 'voxel' = ", f.voxel, " must be a positive size in metres");
  for (int a = 0; a < 3; ++a) {
    if (f.cells[a] < 1 || f.cells[a] > kMaxCells)
      fail(where, ": header key 'cells' holds ", f.cells[a], ", outside [1, ", kMaxCells, "]");
    if (!std::isfinite(f.origin[a])) fail(where, ": header key 'origin' is not finite");
  }
  for (double b : f.box)
    if (!std::isfinite(b)) fail(where, ": header key 'box' is not finite");
  if (f.brick < 1 || f.brick > kMaxBrick)
    fail(where, ": header key 'brick' = ", f.brick, " outside [1, ", kMaxBrick, "]");
  const auto nb = f.bricks();
  const int64_t bricks = nb[0] * nb[1] * nb[2];
  const int64_t stored = h.value("stored_bricks", int64_t(-1));
  if (stored < 0 || stored > bricks)
    fail(where, ": header key 'stored_bricks' = ", stored, " outside [0, ", bricks, "]");
  const int64_t p = f.points_per_brick();
  const size_t expected =
      16 + size_t(length) + size_t(bricks) * 4 + size_t(stored * p) * 4 * (1 + kColorDims);
  if (bytes.size() != expected)
    fail(where, ": ", bytes.size(), " bytes, its header describes ", expected,
         " (truncated or not written by write_baked)");
  size_t at = 16 + length;
  take(bytes, at, f.slot, size_t(bricks));
  take(bytes, at, f.density, size_t(stored * p));
  take(bytes, at, f.color, size_t(stored * p * kColorDims));
  std::vector<char> used(size_t(stored), 0);
  for (int32_t s : f.slot) {
    if (s == -1) continue;
    if (s < 0 || s >= stored) fail(where, ": brick slot ", s, " outside [0, ", stored, ")");
    if (used[size_t(s)]++) fail(where, ": brick slot ", s, " is used twice");
  }
  for (int64_t s = 0; s < stored; ++s)
    if (!used[size_t(s)]) fail(where, ": stored brick ", s, " belongs to no brick");
  for (const auto* v : {&f.density, &f.color})
    for (float x : *v)
      if (!std::isfinite(x)) fail(where, ": holds a value that is not finite");
  return f;
}

}  // namespace th::bake
