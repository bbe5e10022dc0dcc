#include "bake/baked_frame.hpp"

#include <fcntl.h>
#include <fmt/format.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cmath>
#include <cstring>
#include <nlohmann/json.hpp>

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
// Longest header a file may declare: its JSON names a person, a checkpoint path and a few
// numbers (a few hundred bytes).
constexpr uint32_t kMaxHeader = uint32_t{1} << 20;

template <class T>
void append(std::string& out, const std::vector<T>& v) {
  out.append(reinterpret_cast<const char*>(v.data()), v.size() * sizeof(T));
}

// A regular file opened for reading, never a FIFO or a device (fstat on the open descriptor:
// nothing can be swapped in between the check and the read).
class ReadFile {
 public:
  ReadFile(const fs::path& path, const std::string& where) : where_(where) {
    fd_ = ::open(path.c_str(), O_RDONLY | O_CLOEXEC | O_NONBLOCK);
    if (fd_ < 0) fail(where, ": cannot open it (", std::strerror(errno), ")");
    struct stat st {};
    if (::fstat(fd_, &st) != 0 || !S_ISREG(st.st_mode)) {
      const auto type = S_ISFIFO(st.st_mode)   ? fs::file_type::fifo
                        : S_ISCHR(st.st_mode)  ? fs::file_type::character
                        : S_ISBLK(st.st_mode)  ? fs::file_type::block
                        : S_ISDIR(st.st_mode)  ? fs::file_type::directory
                        : S_ISSOCK(st.st_mode) ? fs::file_type::socket
                                               : fs::file_type::unknown;
      ::close(fd_);
      fail(where, " is a ", file_kind(type), ", not a file");
    }
    size_ = uint64_t(st.st_size);
  }
  ~ReadFile() { ::close(fd_); }
  ReadFile(const ReadFile&) = delete;
  ReadFile& operator=(const ReadFile&) = delete;

  uint64_t size() const { return size_; }
  // Reads `count` bytes at `at` into `out`.
  void read(uint64_t at, void* out, uint64_t count) const {
    auto* p = static_cast<char*>(out);
    while (count > 0) {
      const ssize_t n = ::pread(fd_, p, count, off_t(at));
      if (n < 0 && errno == EINTR) continue;
      if (n <= 0) fail(where_, ": cannot read it (", n < 0 ? std::strerror(errno) : "shorter", ")");
      p += n;
      at += uint64_t(n);
      count -= uint64_t(n);
    }
  }
  template <class T>
  void read(uint64_t& at, std::vector<T>& v, uint64_t count) const {
    v.resize(count);
    read(at, v.data(), count * sizeof(T));
    at += count * sizeof(T);
  }

 private:
  std::string where_;
  int fd_ = -1;
  uint64_t size_ = 0;
};

// FNV-1a, 64 bits, over `bytes` continuing from `hash`: which bake a render used.
uint64_t fnv1a(const void* bytes, size_t size, uint64_t hash = 14695981039346656037ull) {
  const auto* p = static_cast<const unsigned char*>(bytes);
  for (size_t i = 0; i < size; ++i) hash = (hash ^ p[i]) * 1099511628211ull;
  return hash;
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
  const std::string where = "bake file '" + path.string() + "'";
  std::error_code ec;
  if (fs::exists(fs::symlink_status(path, ec))) fail(where, " exists: name a new file");
  if (!f.eyes.empty())
    fail(where, ": a bake with a colour per camera (", f.eyes.size(),
         " cameras) serves only those cameras and is not written");
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
  // Written complete beside it, then linked to its name: link() makes the name only where none
  // is, so of two writers of one new file the second is refused, not written over the first.
  const fs::path tmp = create_temporary_beside(path);
  auto discard = [&] { fs::remove(tmp, ec); };
  try {
    write_file_atomic(tmp, out);
  } catch (...) {
    discard();
    throw;
  }
  const int linked = ::link(tmp.c_str(), path.c_str());
  const int err = errno;
  discard();
  if (linked != 0 && err == EEXIST)
    fail(where,
         " appeared while this bake was written (another command wrote it): "
         "its contents are that command's; name a new file");
  if (linked != 0) fail("cannot write ", where, ": ", std::strerror(err));
}

BakedFrame read_baked(const fs::path& path, double max_bytes) {
  const std::string where = "baked frame '" + path.string() + "'";
  refuse_special_file(path, "baked frame");
  const ReadFile in(path, where);
  const uint64_t size = in.size();
  char head[16] = {};
  if (size >= 16) in.read(0, head, 16);
  if (size < 16 || std::memcmp(head, kMagic, sizeof(kMagic)) != 0)
    fail(where,
         ": not a baked frame (no THBAKED header; write one with transhuman-render "
         "--bake-out)");
  uint32_t version = 0, length = 0;
  std::memcpy(&version, head + 8, 4);
  std::memcpy(&length, head + 12, 4);
  if (version != kVersion)
    fail(where, ": format version ", version, ", this build reads version ", kVersion);
  if (length > kMaxHeader)
    fail(where, ": a header of ", length, " bytes, more than a baked frame's (", kMaxHeader, ")");
  if (16 + uint64_t(length) > size) fail(where, ": truncated inside its header");
  std::string text(length, '\0');
  in.read(16, text.data(), length);
  Json h;
  try {
    h = Json::parse(text);
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
  // Every size against the file's length and the memory bound before an array is allocated.
  const int64_t p = f.points_per_brick();
  const uint64_t arrays =
      uint64_t(bricks) * 4 + uint64_t(stored) * uint64_t(p) * 4 * (1 + kColorDims);
  const uint64_t expected = 16 + uint64_t(length) + arrays;
  if (size != expected)
    fail(where, ": ", size, " bytes, its header describes ", expected,
         " (truncated or not written by write_baked)");
  if (max_bytes > 0 && double(arrays) > max_bytes)
    fail(where, ": its arrays take ", fmt::format("{:.1f}", double(arrays) / 1073741824.0),
         " GiB, above the memory limit of ", fmt::format("{:.1f}", max_bytes / 1073741824.0),
         " GiB (max_memory_gb)");
  uint64_t at = 16 + length;
  in.read(at, f.slot, uint64_t(bricks));
  in.read(at, f.density, uint64_t(stored * p));
  in.read(at, f.color, uint64_t(stored * p * kColorDims));
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
  uint64_t hash = fnv1a(head, 16);
  hash = fnv1a(text.data(), text.size(), hash);
  hash = fnv1a(f.slot.data(), f.slot.size() * sizeof(int32_t), hash);
  hash = fnv1a(f.density.data(), f.density.size() * sizeof(float), hash);
  hash = fnv1a(f.color.data(), f.color.size() * sizeof(float), hash);
  f.file = path.string();
  f.digest = fmt::format("{} bytes, FNV-1a 64 {:016x}", size, hash);
  return f;
}

void check_bake_destination(const fs::path& path, const std::string& option,
                            const std::vector<std::pair<std::string, std::string>>& places) {
  const std::string where = option + " '" + path.string() + "'";
  std::error_code ec;
  if (fs::exists(fs::symlink_status(path, ec))) fail(where, " exists: name a new file");
  for (const auto& [what, place] : places) {
    if (place.empty()) continue;
    if (path_within(path, place) || path_within_as_given(path, place))
      fail(where, " lies in ", what, " '", place, "': write the bake outside it");
  }
  const fs::path folder = fs::absolute(path).parent_path();
  if (!fs::is_directory(folder, ec))
    fail(where, ": its folder '", folder.string(), "' ",
         fs::exists(folder, ec) ? "is not a folder" : "does not exist",
         " (it is checked before the bake, which is written last)");
}

}  // namespace th::bake
