#pragma once
// A per-process scratch folder for the fuzz targets whose entry point takes a path: each input
// is written to one file there (under /dev/shm when it exists, so no disk traffic per run) and
// the folder is removed when the fuzzer exits normally.

#include <unistd.h>

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <string>

namespace th::fuzz {

class ScratchDir {
 public:
  ScratchDir() {
    const std::filesystem::path base = std::filesystem::is_directory("/dev/shm")
                                           ? std::filesystem::path("/dev/shm")
                                           : std::filesystem::temp_directory_path();
    dir_ = base / ("th-fuzz-" + std::to_string(getpid()));
    std::filesystem::create_directories(dir_);
  }
  ~ScratchDir() {
    std::error_code ec;
    std::filesystem::remove_all(dir_, ec);
  }
  const std::filesystem::path& path() const { return dir_; }

 private:
  std::filesystem::path dir_;
};

inline const std::filesystem::path& scratch_dir() {
  static const ScratchDir dir;
  return dir.path();
}

// Writes the input to `file_name` (e.g. "in.pth") in the scratch folder and returns its path.
inline std::filesystem::path write_input(const uint8_t* data, size_t size, const char* file_name) {
  const auto path = scratch_dir() / file_name;
  std::ofstream(path, std::ios::binary | std::ios::trunc)
      .write(reinterpret_cast<const char*>(data), static_cast<std::streamsize>(size));
  return path;
}

}  // namespace th::fuzz
