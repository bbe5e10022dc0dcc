// libFuzzer entry for camera path files (video/camera_path.hpp, METHOD 7): each input, written to
// a file, is read as a camera path. th::Error is the expected answer to bad input; a crash, a
// sanitizer report, a leak or any other exception (YAML::Exception, c10::Error) is a bug.
#include <cstddef>
#include <cstdint>

#include "core/error.hpp"
#include "scratch.hpp"
#include "video/camera_path.hpp"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  try {
    th::video::read_camera_path(th::fuzz::write_input(data, size, "path.yaml"));
  } catch (const th::Error&) {
  }
  return 0;
}
