#pragma once
// The one user-facing error type of the project.
//
// Errors are values for users, exceptions for bugs: a missing file, a bad config key or a
// corrupt pickle throws th::Error with a message that names the file, key or value; the apps
// catch it at the top and print that one line. Broken invariants use TORCH_CHECK instead.

#include <sstream>
#include <stdexcept>
#include <string>

namespace th {

class Error : public std::runtime_error {
 public:
  explicit Error(const std::string& message) : std::runtime_error(message) {}
};

// Builds the message from pieces: th::fail("cannot open '", path, "': ", reason).
template <class... Parts>
[[noreturn]] void fail(const Parts&... parts) {
  std::ostringstream message;
  (message << ... << parts);
  throw Error(message.str());
}

}  // namespace th
