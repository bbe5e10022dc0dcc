#pragma once
// Catch2 3 (Debian 13) under the Catch2 2 header that the tests include (Debian 12 has 2.13):
// on the include path only when CMake finds Catch2 3 (cmake/TransHuman.cmake, th_test).

#include <catch2/catch_all.hpp>
#include <string>

using Catch::Approx;

namespace Catch {
// Catch2 2's substring matcher, renamed ContainsSubstring in 3.
inline Matchers::StringContainsMatcher Contains(const std::string& text,
                                                CaseSensitive cs = CaseSensitive::Yes) {
  return Matchers::ContainsSubstring(text, cs);
}
}  // namespace Catch
