// libFuzzer entry for the untrusted-input readers of lib/io (METHOD 1.4): arbitrary bytes go to
// parse_pickle, parse_npy, parse_npy_value and parse_npz. th::Error is the expected answer to
// bad input; a crash, a sanitizer report, a leak or any other exception is a bug. Whatever
// parses as a pickle must also survive pickle_bytes and read back equal.
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <string>

#include "core/error.hpp"
#include "io/npy.hpp"
#include "io/pickle.hpp"

namespace {

void round_trip(const th::io::Value& value) {
  for (int protocol = 2; protocol <= 4; ++protocol) {
    std::string bytes;
    try {
      bytes = th::io::pickle_bytes(value, protocol);
    } catch (const th::Error&) {
      return;  // numpy.dtype objects and the like cannot be written
    }
    if (!(th::io::parse_pickle(bytes, "rewritten.pkl") == value)) std::abort();
  }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string bytes(reinterpret_cast<const char*>(data), size);
  try {
    round_trip(th::io::parse_pickle(bytes, "fuzz.pkl"));
  } catch (const th::Error&) {
  }
  try {
    th::io::parse_npy(bytes, "fuzz.npy");
  } catch (const th::Error&) {
  }
  try {
    th::io::parse_npy_value(bytes, "fuzz.npy");
  } catch (const th::Error&) {
  }
  try {
    th::io::parse_npz(bytes, "fuzz.npz");
  } catch (const th::Error&) {
  }
  return 0;
}
