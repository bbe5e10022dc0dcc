#include <catch2/catch.hpp>

#include "core/progress.hpp"

TEST_CASE("durations are formatted for people", "[progress]") {
  CHECK(th::Progress::format_duration(4.23) == "4.2s");
  CHECK(th::Progress::format_duration(185) == "3m05s");
  CHECK(th::Progress::format_duration(3720) == "1h02m");
  CHECK(th::Progress::format_duration(-1) == "?");
}

TEST_CASE("the status line shows count, percentage, rate and ETA", "[progress]") {
  th::Progress p("train", 200, "step");
  p.set_interactive(false);
  p.advance(50, "loss 0.1");
  const std::string line = p.status_line("loss 0.1");
  CHECK_THAT(line, Catch::Contains("50/200"));
  CHECK_THAT(line, Catch::Contains(" 25%"));
  CHECK_THAT(line, Catch::Contains("step/s"));
  CHECK_THAT(line, Catch::Contains("ETA"));
  CHECK_THAT(line, Catch::Contains("loss 0.1"));
  p.finish();
}

TEST_CASE("a loop of unknown length shows count and rate without ETA", "[progress]") {
  th::Progress p("scan", 0, "file");
  p.set_interactive(false);
  p.advance(3);
  const std::string line = p.status_line("");
  CHECK_THAT(line, Catch::Contains("3 file"));
  CHECK_THAT(line, !Catch::Contains("ETA"));
}
