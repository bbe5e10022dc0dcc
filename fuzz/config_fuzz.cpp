// libFuzzer entry for YAML config files (core/config_io.hpp): each input, written to a file, is
// loaded as the project's whole config tree (parents, duplicate and empty keys, types, unknown
// keys, the sections' validate_section checks). configs/default.yaml sits next to it, so that
// `parent: default.yaml` (every config but the default names it) merges as in real use.
// th::Error is the expected answer to bad input; a crash, a sanitizer report, a leak or any
// other exception (YAML::Exception included) is a bug.
#include <cstddef>
#include <cstdint>
#include <filesystem>

#include "core/config.hpp"
#include "core/error.hpp"
#include "scratch.hpp"

extern "C" int LLVMFuzzerInitialize(int*, char***) {
  std::filesystem::copy_file(TH_FUZZ_CONFIG_DIR "/default.yaml", th::fuzz::scratch_dir() / "default.yaml",
                             std::filesystem::copy_options::overwrite_existing);
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  try {
    th::config::load<th::Config>(th::fuzz::write_input(data, size, "config.yaml"));
  } catch (const th::Error&) {
  }
  return 0;
}
