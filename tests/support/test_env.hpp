#pragma once
// Helpers shared by the test executables: scratch folders and the Python used for fixtures.

#include <unistd.h>

#include <cstdlib>
#include <filesystem>
#include <string>

namespace th::test {

// A fresh, empty folder under the build tree's test_tmp (TH_TEST_TMP), unique per name and per
// process: CTest runs test cases of one executable in parallel processes, which must not clear
// each other's folders.
inline std::filesystem::path scratch_dir(const std::string& name) {
  const char* root = std::getenv("TH_TEST_TMP");
  std::filesystem::path dir =
      std::filesystem::path(root ? root : std::filesystem::temp_directory_path().string()) /
      (name + "." + std::to_string(::getpid()));
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  return dir;
}

// Debian's python3 (with python3-numpy, -torch, -skimage): tests run reference scripts with it.
inline std::string python() {
  const char* py = std::getenv("TH_PYTHON");
  return (py && *py) ? py : "/usr/bin/python3";
}

// Runs `python3 <script> <args>` from the repository root; returns the exit status.
inline int run_python(const std::string& script, const std::string& args) {
  const std::string cmd = python() + " " + script + " " + args;
  return std::system(cmd.c_str());
}

// The tiny synthetic dataset (configs/synth/tiny.yaml) that CTest's fixture test
// `synth_tiny_dataset` generates before the tests that need it.
// `exact`: the same people with fitting noise off (synth_tiny_exact).
inline std::filesystem::path tiny_dataset(bool exact = false) {
  const char* root = std::getenv("TH_TEST_TMP");
  return std::filesystem::path(root ? root : "build/test_tmp") /
         (exact ? "synth_tiny_exact" : "synth_tiny");
}

}  // namespace th::test
