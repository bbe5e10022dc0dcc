// The page writer without a browser: escaping, what index.html embeds, what the folder holds.
#include <catch2/catch.hpp>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <sstream>

#include "core/error.hpp"
#include "report/report.hpp"
#include "support/test_env.hpp"

namespace fs = std::filesystem;

namespace {

std::string read_all(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

// The data index.html embeds (window.TH_REPORT = {...};), parsed as JSON.
nlohmann::json page_data(const std::string& html) {
  const std::string start = "window.TH_REPORT = ";
  const size_t b = html.find(start);
  REQUIRE(b != std::string::npos);
  const size_t e = html.find(";\n</script>", b);
  REQUIRE(e != std::string::npos);
  return nlohmann::json::parse(html.substr(b + start.size(), e - b - start.size()));
}

void write(const fs::path& p, const std::string& text) {
  fs::create_directories(p.parent_path());
  std::ofstream(p, std::ios::binary) << text;
}

// An evaluation folder as transhuman-eval leaves it, with two images and their panels.
fs::path fake_eval(const fs::path& dir) {
  write(
      dir / "summary.json",
      "{\"setting\": \"identity\", \"images\": 2, \"psnr\": 21.5, \"ssim\": 0.7, \"lpips\": null, "
      "\"lpips_available\": \"no\", \"seconds_per_image\": 0.5}\n");
  write(dir / "per_image.csv",
        "human,frame,view,psnr,ssim,lpips,seconds,points,culled_points\n"
        "CoreView_s03,0,3,20.000000,0.600000,n/a,0.5,10,1\nCoreView_s03,2,5,23.000000,0.800000,n/"
        "a,0.5,10,1\n");
  write(dir / "config.yaml", "note: </script><b>\n");
  write(dir / "images" / "CoreView_s03_f0000_v03.png", "png");
  write(dir / "images" / "CoreView_s03_f0002_v05.png", "png");
  return dir;
}

}  // namespace

TEST_CASE("script_json escapes quotes, newlines and anything that could close the script element",
          "[report]") {
  using th::report::script_json;
  CHECK(script_json("a\"b\\c\nd") == "\"a\\\"b\\\\c\\nd\"");
  CHECK(script_json("</script><!--") == "\"\\u003c/script\\u003e\\u003c!--\"");
  CHECK(script_json(std::string("\x01", 1)) == "\"\\u0001\"");
  CHECK(script_json("λ") == "\"λ\"");                                  // UTF-8 passes through
  CHECK(script_json(std::string("a\xff", 2)) == "\"a\xef\xbf\xbd\"");  // not UTF-8: U+FFFD
  // Still JSON, and the same value.
  const nlohmann::ordered_json value = {{"k&y", {"</script>", nullptr, 1.5, true}}};
  CHECK(nlohmann::ordered_json::parse(script_json(value)) == value);
}

TEST_CASE("an evaluation page embeds the outputs and refers to the panels where they lie",
          "[report]") {
  const fs::path eval = fake_eval(th::test::scratch_dir("report_eval") / "eval_identity");
  th::report::PageSources sources;
  sources.evals = {eval};
  const fs::path page = th::report::write_page(sources, eval);
  CHECK(page == eval / "index.html");
  const std::string html = read_all(page);
  CHECK_THAT(html, Catch::Contains("\\\"psnr\\\": 21.5"));  // summary.json, as text
  const auto summary =
      nlohmann::json::parse(page_data(html)["evals"][0]["summary"].get<std::string>());
  CHECK(summary["setting"] == "identity");
  CHECK(summary["psnr"] == 21.5);
  CHECK(summary["lpips"].is_null());
  CHECK_THAT(html, Catch::Contains("\"./images/CoreView_s03_f0002_v05.png\""));
  CHECK(html.find("</script><b>") == std::string::npos);  // the config cannot break out
  CHECK(fs::exists(eval / "report.js"));
  CHECK(fs::exists(eval / "report.css"));
  CHECK_FALSE(fs::exists(eval / "mesh.js"));  // no mesh, no viewer
}

TEST_CASE("a demo page copies what it shows into its folder", "[report]") {
  const fs::path root = th::test::scratch_dir("report_demo");
  const fs::path eval = fake_eval(root / "run" / "eval_identity");
  write(root / "run" / "orbit" / "frames" / "frame_0000.png", "png");
  write(root / "run" / "orbit" / "video.mp4", "mp4");
  write(root / "run" / "mesh" / "p.ply", "ply\nformat binary_little_endian 1.0\nend_header\n");
  th::report::PageSources sources;
  sources.evals = {eval};
  sources.orbit = root / "run" / "orbit";
  sources.mesh = root / "run" / "mesh" / "p.ply";
  const fs::path out = root / "report";
  th::report::write_page(sources, out);
  CHECK(fs::exists(out / "eval_identity" / "images" / "CoreView_s03_f0000_v03.png"));
  CHECK(fs::exists(out / "eval_identity" / "summary.json"));
  CHECK(fs::exists(out / "orbit" / "frames" / "frame_0000.png"));
  CHECK(fs::exists(out / "orbit" / "video.mp4"));
  CHECK(fs::exists(out / "p.ply"));
  // The mesh as base64 (a file:// page may not fetch it): "ply\nfor" encodes to "cGx5CmZvcm".
  CHECK_THAT(read_all(out / "mesh.js"), Catch::Contains("\"cGx5CmZvcm"));
  const std::string html = read_all(out / "index.html");
  CHECK_THAT(html, Catch::Contains("\"./eval_identity/images/CoreView_s03_f0000_v03.png\""));
  CHECK(html.find(root.string()) == std::string::npos);  // nothing refers outside the folder
  // three.js comes with libjs-three, which scripts/install-deps.sh installs: its absence is a
  // broken set-up, not a case to skip.
  INFO(
      "three.js not found (TH_THREE_JS_DIR, /usr/share/javascript/three, /usr/share/nodejs/three)");
  REQUIRE_FALSE(th::report::find_three_js().empty());
  CHECK(fs::exists(out / "three" / "three.min.js"));
  CHECK_THAT(html, Catch::Contains("<script src=\"three/PLYLoader.js\"></script>"));
}

TEST_CASE("folder names become safe relative links, and a link with a script scheme is refused",
          "[report]") {
  const fs::path root = th::test::scratch_dir("report_names");
  const fs::path eval = fake_eval(root / "javascript:alert(1);0");
  th::report::PageSources sources;
  sources.evals = {eval};
  sources.links = {{"home", "https://example.org/th"}, {"runs", "../runs/"}};
  const std::string html = read_all(th::report::write_page(sources, root / "page"));
  CHECK_THAT(html, Catch::Contains(
                       "\"./javascript%3Aalert%281%29%3B0/images/CoreView_s03_f0000_v03.png\""));
  // The name is shown as text; no link starts with it.
  CHECK(html.find("\"javascript:alert(1);0/") == std::string::npos);
  for (const char* bad :
       {"javascript:alert(1)", "JavaScript:alert(1)", "data:text/html,<b>", "vbscript:x"}) {
    CAPTURE(bad);
    sources.links = {{"x", bad}};
    CHECK_THROWS_WITH(th::report::write_page(sources, root / "page2"),
                      Catch::Contains(std::string("report: link 'x' = '") + bad +
                                      "': only relative links and http(s) URLs are allowed"));
  }
  CHECK_FALSE(fs::exists(root / "page2"));  // refused before anything is written
}

TEST_CASE("a person's name with a comma and quotes survives per_image.csv (RFC 4180 quoting)",
          "[report]") {
  const fs::path eval = fake_eval(th::test::scratch_dir("report_csv") / "eval");
  write(eval / "per_image.csv",
        "human,frame,view,psnr,ssim,lpips,seconds,points,culled_points\n"
        "\"Core,\"\"View\"\"\",0,3,20.000000,0.600000,n/a,0.5,10,1\n");
  write(eval / "images" / "Core,\"View\"_f0000_v03.png", "png");
  th::report::PageSources sources;
  sources.evals = {eval};
  const std::string html = read_all(th::report::write_page(sources, eval));
  CHECK_THAT(html, Catch::Contains("\"./images/Core%2C%22View%22_f0000_v03.png\""));
}

TEST_CASE("a missing summary.json is an error naming the file", "[report]") {
  const fs::path dir = th::test::scratch_dir("report_missing");
  th::report::PageSources sources;
  sources.evals = {dir};
  CHECK_THROWS_WITH(th::report::write_page(sources, dir),
                    Catch::Contains((dir / "summary.json").string()));
}

TEST_CASE("a summary.json that is not the evaluator's JSON is an error naming the file and key",
          "[report]") {
  const fs::path eval = fake_eval(th::test::scratch_dir("report_bad_summary") / "e");
  th::report::PageSources sources;
  sources.evals = {eval};
  const std::string file = "'" + (eval / "summary.json").string() + "'";
  const std::pair<std::string, std::string> cases[] = {
      {"{\"setting\": \"identity\", \"psnr\": 20.", file + " is not JSON ("},
      {"{\"setting\": \"identity\", \"images\": 1, \"psnr\": NaN, \"ssim\": 0.5, \"lpips\": null}",
       file + ": 'psnr' = 'NaN' is not a finite number (or null)"},
      {"{\"setting\": \"identity\", \"images\": 1, \"psnr\": 20, \"ssim\": -Infinity, \"lpips\": "
       "null}",
       file + ": 'ssim' = '-Infinity' is not a finite number (or null)"},
      {"{\"setting\": \"identity\", \"images\": 1, \"psnr\": \"20\", \"ssim\": 0.5, \"lpips\": "
       "null}",
       file + ": 'psnr' = \"20\" is not a number"},
      {"{\"setting\": \"identity\", \"images\": 1, \"psnr\": 20, \"ssim\": 0.5}",
       file + " has no 'lpips'"},
      {"{\"setting\": [1], \"images\": 1, \"psnr\": 20, \"ssim\": 0.5, \"lpips\": null}",
       file + ": 'setting' is not a single value"},
      {"[1, 2]", file + " is not a JSON object"},
      {"\n", file + " is not a JSON object"},
  };
  for (const auto& [text, message] : cases) {
    CAPTURE(text);
    write(eval / "summary.json", text);
    CHECK_THROWS_WITH(th::report::write_page(sources, eval),
                      Catch::Contains("report: evaluation summary " + message));
  }
}

TEST_CASE("an ablation page holds every row and links each row's own page", "[report]") {
  const fs::path root = th::test::scratch_dir("report_ablation");
  fake_eval(root / "full" / "eval_identity");
  fake_eval(root / "fdi_wo_h" / "eval_identity");
  write(root / "full" / "eval_identity" / "index.html", "<html></html>");
  const fs::path page = th::report::write_ablation_page(
      {{"full", "the paper's model", root / "full" / "eval_identity", 600},
       {"fdi_wo_h", "without the human branch", root / "fdi_wo_h" / "eval_identity", NAN}},
      "ablations", root);
  const auto rows = page_data(read_all(page))["rows"];
  REQUIRE(rows.size() == 2);
  CHECK(rows[0]["name"] == "full");
  CHECK(rows[0]["page"] == "./full/eval_identity/index.html");
  CHECK(rows[0]["train_seconds"] == 600);
  CHECK(rows[1]["name"] == "fdi_wo_h");
  CHECK(rows[1]["page"].is_null());
  CHECK(rows[1]["train_seconds"].is_null());
}

namespace {

// Every file under `dir` with its contents, for "nothing else changed" checks.
std::map<std::string, std::string> snapshot(const fs::path& dir) {
  std::map<std::string, std::string> files;
  for (const auto& e : fs::recursive_directory_iterator(dir))
    if (e.is_regular_file()) files[fs::relative(e.path(), dir).string()] = read_all(e.path());
  return files;
}

}  // namespace

TEST_CASE(
    "an evaluation's copy is named by its resolved folder, uniquely, and never lands outside --out",
    "[report]") {
  const fs::path root = th::test::scratch_dir("report_copy_names");
  write(root / "run" / "config.yaml", "the run's own config\n");
  fake_eval(root / "e");
  write(root / "e" / "config.yaml", "the evaluation's config\n");
  th::report::PageSources sources;

  // A trailing separator: the copy goes to out/e, not into out itself.
  sources.evals = {root / "e" / ""};
  th::report::write_page(sources, root / "run");
  CHECK(read_all(root / "run" / "config.yaml") == "the run's own config\n");
  CHECK(read_all(root / "run" / "e" / "config.yaml") == "the evaluation's config\n");

  // ".." is resolved: the folder's own name, inside --out; nothing beside the page's folder.
  fs::create_directories(root / "c");
  sources.evals = {root / "e" / "images" / ".."};
  th::report::write_page(sources, root / "c" / "page");
  CHECK(fs::exists(root / "c" / "page" / "e" / "summary.json"));
  CHECK(std::vector<fs::path>(fs::directory_iterator(root / "c"), {}) ==
        std::vector<fs::path>{root / "c" / "page"});

  // Two folders with the same name: two copies, each page entry showing its own images.
  fake_eval(root / "a" / "e");
  fake_eval(root / "b" / "e");
  write(root / "a" / "e" / "images" / "CoreView_s03_f0000_v03.png", "a's panel");
  write(root / "b" / "e" / "images" / "CoreView_s03_f0000_v03.png", "b's panel");
  sources.evals = {root / "a" / "e", root / "b" / "e"};
  const std::string html = read_all(th::report::write_page(sources, root / "two"));
  CHECK(read_all(root / "two" / "e" / "images" / "CoreView_s03_f0000_v03.png") == "a's panel");
  CHECK(read_all(root / "two" / "e-2" / "images" / "CoreView_s03_f0000_v03.png") == "b's panel");
  const auto evals = page_data(html)["evals"];
  REQUIRE(evals.size() == 2);
  CHECK(evals[0]["name"] == "e");
  CHECK(evals[1]["name"] == "e-2");
  CHECK_THAT(html, Catch::Contains("\"./e-2/images/CoreView_s03_f0000_v03.png\""));

  // A folder named like one of the page's own files takes another name.
  fake_eval(root / "x" / "orbit");
  sources.evals = {root / "x" / "orbit"};
  th::report::write_page(sources, root / "named");
  CHECK(fs::exists(root / "named" / "orbit-2" / "summary.json"));
}

TEST_CASE("the report writes nothing through a link in --out", "[report]") {
  const fs::path root = th::test::scratch_dir("report_links");
  fake_eval(root / "e");
  write(root / "elsewhere" / "keep.txt", "kept");
  fs::create_directories(root / "out");
  fs::create_directory_symlink(root / "elsewhere", root / "out" / "e");
  const auto before = snapshot(root / "elsewhere");
  th::report::PageSources sources;
  sources.evals = {root / "e"};
  CHECK_THROWS_WITH(
      th::report::write_page(sources, root / "out"),
      Catch::Contains("'" + (root / "out" / "e").string() + "' in --out is a symbolic link"));
  CHECK(snapshot(root / "elsewhere") == before);
  // A link in place of one of the page's files: refused too, its target unchanged.
  fs::remove(root / "out" / "e");
  fs::create_symlink(root / "elsewhere" / "keep.txt", root / "out" / "report.js");
  CHECK_THROWS_WITH(th::report::write_page(sources, root / "out"),
                    Catch::Contains("is a symbolic link"));
  CHECK(read_all(root / "elsewhere" / "keep.txt") == "kept");
}
