#include <catch2/catch.hpp>
#include <fstream>
#include <sstream>

#include "core/error.hpp"
#include "core/process.hpp"
#include "support/test_env.hpp"

namespace fs = std::filesystem;

TEST_CASE("a program's arguments are passed as they are, never read by a shell", "[process]") {
  const fs::path dir = th::test::scratch_dir("run_program");
  const std::string hostile =
      "x';touch " + (dir / "pwned").string() + ";'$(touch " + (dir / "pwned2").string() + ")";
  const fs::path log = dir / "echo.log";
  CHECK(th::run_program({"echo", hostile, "two words"}, log.string()) == 0);
  std::stringstream text;
  text << std::ifstream(log).rdbuf();
  CHECK(text.str() == hostile + " two words\n");
  CHECK_FALSE(fs::exists(dir / "pwned"));
  CHECK_FALSE(fs::exists(dir / "pwned2"));
}

TEST_CASE("a program's exit status is returned, and one that cannot start is an error naming it",
          "[process]") {
  CHECK(th::run_program({"sh", "-c", "exit 3"}) == 3);
  CHECK(th::run_program({"sh", "-c", "kill -TERM $$"}) == 128 + 15);
  CHECK_THROWS_WITH(th::run_program({"/nonexistent/program"}),
                    Catch::Contains("cannot start '/nonexistent/program'"));
}
