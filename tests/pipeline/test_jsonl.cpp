// metrics.jsonl and summary.json lines: JSON that nlohmann (and Python's json) reads back, in
// the layout tools grep for.
#include <catch2/catch.hpp>
#include <cmath>
#include <fstream>
#include <nlohmann/json.hpp>
#include <string>

#include "pipeline/jsonl.hpp"
#include "support/test_env.hpp"

namespace fs = std::filesystem;
using th::pipeline::JsonLine;

TEST_CASE("a metrics line keeps its key order and the layout tools grep for", "[jsonl]") {
  JsonLine line;
  line.add("step", 12).add("epoch", int64_t(3)).add("lr", 5e-4);
  line.add("setting", std::string("identity"));
  CHECK(line.str() == "{\"step\": 12, \"epoch\": 3, \"lr\": 0.0005, \"setting\": \"identity\"}");
}

TEST_CASE("metrics keep 9 significant digits and write NaN and infinities as null", "[jsonl]") {
  JsonLine line;
  line.add("loss", double(0.1f)).add("psnr", 21.5).add("lpips", NAN);
  line.add("big", INFINITY).add("small", -INFINITY);
  // 0.1f is 0.100000001490116...: a float's digits, not the double's.
  CHECK(line.str() ==
        "{\"loss\": 0.100000001, \"psnr\": 21.5, \"lpips\": null, \"big\": null, \"small\": null}");
  const auto back = nlohmann::json::parse(line.str());
  CHECK(back["loss"].get<double>() == Approx(0.1).epsilon(1e-8));
  CHECK(back["lpips"].is_null());
}

TEST_CASE("strings needing escapes round-trip through nlohmann::json::parse", "[jsonl]") {
  // A quote, a backslash, a newline, a tab, a control character, a non-ASCII letter.
  const std::string name = std::string("Core\"View\\s03\n\tend") + '\x01' + "λ";
  JsonLine line;
  line.add(name, name).add("step", 1);
  const std::string text = line.str();
  CHECK(text.find('\n') == std::string::npos);  // one line
  const auto back = nlohmann::ordered_json::parse(text);
  REQUIRE(back.size() == 2);
  CHECK(back.begin().key() == name);
  CHECK(back[name] == name);
  CHECK(back["step"] == 1);
}

TEST_CASE("a string that is not UTF-8 is written as U+FFFD, not refused", "[jsonl]") {
  const std::string text = JsonLine()
                               .add("human", std::string("a\xff"
                                                         "b"))
                               .str();
  CHECK(text ==
        "{\"human\": \"a\xef\xbf\xbd"
        "b\"}");
  CHECK(nlohmann::json::parse(text)["human"] ==
        "a\xef\xbf\xbd"
        "b");
}

TEST_CASE("a JSON-lines file gets one parsable object per line, appended", "[jsonl]") {
  const fs::path file = th::test::scratch_dir("pipeline_jsonl") / "metrics.jsonl";
  {
    th::pipeline::JsonlWriter log(file);
    log.write(JsonLine().add("step", 1).add("note", std::string("a \"quoted\" word")));
  }
  {
    th::pipeline::JsonlWriter log(file);  // a resumed run appends
    log.write(JsonLine().add("step", 2).add("loss", 0.25));
  }
  std::ifstream in(file);
  std::string line;
  int64_t step = 0;
  while (std::getline(in, line)) CHECK(nlohmann::json::parse(line)["step"] == ++step);
  CHECK(step == 2);
}
