#pragma once
// Helpers shared by the test executables: scratch folders and the Python used for fixtures.

#include <unistd.h>

#include <cstdlib>
#include <filesystem>
#include <mutex>
#include <string>
#include <system_error>
#include <vector>

namespace th::test {

// Where the build tree, its test scratch root and the fixtures' Python are. CMake compiles them
// into each test executable (th_test); an environment variable of the same name overrides them
// for a test binary run by hand against another tree. (They are not passed through CTest's
// ENVIRONMENT property: Catch2 3's catch_discover_tests flattens a list-valued property, which
// kept only the first of several variables.)
namespace detail {
inline std::string setting(const char* name, const char* compiled) {
  const char* v = std::getenv(name);
  return (v && *v) ? std::string(v) : std::string(compiled);
}
}  // namespace detail

#ifndef TH_TEST_BUILD_DIR
#define TH_TEST_BUILD_DIR "build"
#endif
#ifndef TH_TEST_PYTHON
#define TH_TEST_PYTHON "/usr/bin/python3"
#endif

inline std::filesystem::path build_dir() {
  return detail::setting("TH_BUILD_DIR", TH_TEST_BUILD_DIR);
}
inline std::filesystem::path test_tmp_root() {
  return detail::setting("TH_TEST_TMP", (build_dir() / "test_tmp").c_str());
}

namespace detail {

// The scratch folders this process made; they are removed when it exits (a CTest run makes one
// per test case and process, ~2 GB in all, which a repeated run would otherwise pile up).
// TH_KEEP_TEST_TMP=1 keeps them for a look after a failure.
class ScratchRegistry {
 public:
  static ScratchRegistry& instance() {
    static ScratchRegistry registry;
    return registry;
  }
  void add(const std::filesystem::path& dir) {
    std::lock_guard<std::mutex> lock(mutex_);
    dirs_.push_back(dir);
  }
  ~ScratchRegistry() {
    const char* keep = std::getenv("TH_KEEP_TEST_TMP");
    if (keep && *keep && std::string(keep) != "0") return;
    if (::getpid() != owner_) return;  // a forked child leaves its parent's folders alone
    for (const auto& dir : dirs_) {
      std::error_code ignored;  // a folder a test removed itself is fine
      std::filesystem::remove_all(dir, ignored);
    }
  }

 private:
  ScratchRegistry() : owner_(::getpid()) {}
  pid_t owner_;
  std::mutex mutex_;
  std::vector<std::filesystem::path> dirs_;
};

}  // namespace detail

// A fresh, empty folder under the build tree's test_tmp (TH_TEST_TMP), unique per name and per
// process: CTest runs test cases of one executable in parallel processes, which must not clear
// each other's folders. Removed when the process exits unless TH_KEEP_TEST_TMP=1.
inline std::filesystem::path scratch_dir(const std::string& name) {
  const std::filesystem::path dir = test_tmp_root() / (name + "." + std::to_string(::getpid()));
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  detail::ScratchRegistry::instance().add(dir);
  return dir;
}

// Debian's python3 (with python3-numpy, -torch, -skimage): tests run reference scripts with it.
inline std::string python() { return detail::setting("TH_PYTHON", TH_TEST_PYTHON); }

// Runs `python3 <script> <args>` from the repository root; returns the exit status.
inline int run_python(const std::string& script, const std::string& args) {
  const std::string cmd = python() + " " + script + " " + args;
  return std::system(cmd.c_str());
}

// The tiny synthetic dataset (configs/synth/tiny.yaml) that CTest's fixture test
// `synth_tiny_dataset` generates before the tests that need it.
// `exact`: the same people with fitting noise off (synth_tiny_exact).
inline std::filesystem::path tiny_dataset(bool exact = false) {
  return test_tmp_root() / (exact ? "synth_tiny_exact" : "synth_tiny");
}
// The tiny dataset's people in EasyMocap's layout (`synth_tiny_easymocap_dataset`).
inline std::filesystem::path tiny_easymocap_dataset() {
  return test_tmp_root() / "synth_tiny_easymocap";
}

}  // namespace th::test
