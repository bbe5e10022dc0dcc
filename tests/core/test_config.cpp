#include <spdlog/sinks/ostream_sink.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <catch2/catch.hpp>
#include <cmath>
#include <fstream>
#include <iomanip>
#include <sstream>

#include "core/config.hpp"
#include "support/test_env.hpp"

namespace fs = std::filesystem;
using th::Config;
using namespace th::config;

namespace {

fs::path write_file(const fs::path& dir, const std::string& name, const std::string& text) {
  std::ofstream(dir / name) << text;
  return dir / name;
}

// Every key path of a YAML map ("a.b.c").
void collect_keys(const YAML::Node& node, const std::string& prefix,
                  std::vector<std::string>& out) {
  for (const auto& kv : node) {
    const std::string key =
        prefix.empty() ? kv.first.as<std::string>() : prefix + "." + kv.first.as<std::string>();
    if (kv.second.IsMap())
      collect_keys(kv.second, key, out);
    else
      out.push_back(key);
  }
}

std::string message_of(const std::function<void()>& f) {
  try {
    f();
  } catch (const th::Error& e) {
    return e.what();
  }
  return "<no error>";
}

}  // namespace

TEST_CASE("default.yaml lists every option with the compiled-in defaults", "[config]") {
  const YAML::Node file = YAML::LoadFile("configs/default.yaml");
  const YAML::Node defaults = to_tree(Config{});
  std::vector<std::string> file_keys, default_keys;
  collect_keys(file, "", file_keys);
  collect_keys(defaults, "", default_keys);
  std::sort(file_keys.begin(), file_keys.end());
  std::sort(default_keys.begin(), default_keys.end());
  CHECK(file_keys == default_keys);
  const Config loaded = load<Config>("configs/default.yaml");
  CHECK(YAML::Dump(to_tree(loaded)) == YAML::Dump(defaults));
}

TEST_CASE("every key is declared with a description, and the listing holds every key", "[config]") {
  const auto declared = keys<Config>();
  std::vector<std::string> listed, written;
  for (const auto& k : declared) {
    listed.push_back(k.key);
    CHECK_FALSE(k.doc.empty());
    if (k.doc.empty()) UNSCOPED_INFO("no description: " << k.key);
  }
  collect_keys(to_tree(Config{}), "", written);
  std::sort(listed.begin(), listed.end());
  std::sort(written.begin(), written.end());
  CHECK(listed == written);
  const std::string text = describe(declared);
  CHECK_THAT(text, Catch::Contains("render.samples") && Catch::Contains("in [2, 4096]") &&
                       Catch::Contains("the paper's fast variant"));
  CHECK(std::count(text.begin(), text.end(), '\n') == long(declared.size()));
}

namespace {

// `value` as YAML text that reads back exactly.
std::string yaml_number(double value, bool integer) {
  std::ostringstream out;
  if (integer)
    out << int64_t(value);
  else
    out << std::setprecision(17) << value;
  return out.str();
}

// The defaults as a tree with the leaf at `key` ("a.b.c") set to `text`.
YAML::Node with_leaf(const std::string& key, const std::string& text) {
  YAML::Node root = to_tree(Config{});
  std::stringstream parts(key);
  std::string part;
  std::vector<std::string> path;
  while (std::getline(parts, part, '.')) path.push_back(part);
  std::vector<YAML::Node> chain{root};
  for (size_t i = 0; i + 1 < path.size(); ++i) chain.push_back(chain.back()[path[i]]);
  chain.back()[path.back()] = YAML::Load(text);
  return root;
}

}  // namespace

TEST_CASE("every declared range holds its default and refuses values outside it, naming the key",
          "[config]") {
  int ranged = 0;
  for (const auto& k : keys<Config>()) {
    if (k.accepts.empty()) continue;
    ++ranged;
    INFO(k.key << " (" << k.accepts << ")");
    const bool integer = k.type == "an integer";
    CHECK(k.range.holds(YAML::Load(k.value).as<double>()));
    std::vector<double> outside;
    const double step = integer ? 1 : std::max(1e-6, 1e-6 * std::abs(k.range.high));
    if (std::isfinite(k.range.low))
      outside.push_back(k.range.low_open
                            ? k.range.low
                            : k.range.low -
                                  (integer ? 1 : std::max(1e-6, 1e-6 * std::abs(k.range.low))));
    if (std::isfinite(k.range.high))
      outside.push_back(k.range.high_open ? k.range.high : k.range.high + step);
    for (const double x : outside) {
      const std::string text = yaml_number(x, integer);
      INFO("value " << text);
      CHECK_THAT(message_of([&] { from_tree<Config>(with_leaf(k.key, text)); }),
                 Catch::Contains("config key '" + k.key + "' = ") &&
                     Catch::Contains("must be " + k.accepts));
    }
  }
  CHECK(ranged >= 30);
  // Numbers must be finite, ranged or not.
  CHECK_THAT(message_of([] { from_tree<Config>(with_leaf("train.lr", ".nan")); }),
             Catch::Contains("config key 'train.lr' = nan: must be finite"));
  CHECK_THAT(message_of([] { from_tree<Config>(with_leaf("seed", "1")); }),
             Catch::Contains("<no error>"));
  CHECK_THAT(message_of([] { from_tree<Config>(with_leaf("data.jitter.hue", "[0, .inf]")); }),
             Catch::Contains("config key 'data.jitter.hue[1]' = inf: must be finite"));
  // A section built in code is checked the same way.
  th::RenderConfig render;
  render.samples = 1;
  CHECK_THAT(message_of([&] { check(render, "render"); }),
             Catch::Contains("config key 'render.samples' = 1: must be in [2, 4096]"));
  th::TrainConfig train;
  train.warmup_epochs = train.epochs;
  CHECK_THAT(message_of([&] { check(train, "train"); }),
             Catch::Contains("config key 'train.warmup_epochs'"));
}

TEST_CASE("a child config inherits its parent and overrides win over both", "[config]") {
  const fs::path dir = th::test::scratch_dir("config_inherit");
  write_file(
      dir, "base.yaml",
      "train:\n  lr: 0.001\n  epochs: 10\n  warmup_epochs: 1\nmodel:\n  dparf:\n    nk: 3\n");
  write_file(dir, "child.yaml", "parent: base.yaml\ntrain:\n  epochs: 20\n");
  const Config c = load<Config>(dir / "child.yaml", {"model.dparf.nk=5", "data.ratio=0.25"});
  CHECK(c.train.lr == Approx(0.001));
  CHECK(c.train.epochs == 20);
  CHECK(c.model.dparf.nk == 5);
  CHECK(c.data.ratio == Approx(0.25));
  CHECK(c.train.iters_per_epoch == 500);  // untouched default
}

TEST_CASE("a misspelt key fails naming the key and the likely intended one", "[config]") {
  const fs::path dir = th::test::scratch_dir("config_typo");
  write_file(dir, "typo.yaml",
             "train:\n  learning_rat: 0.1\n  lr: 0.1\nmodel:\n  dparf:\n    nkk: 3\n");
  const std::string msg = message_of([&] { load<Config>(dir / "typo.yaml"); });
  CHECK_THAT(msg, Catch::Contains("model.dparf.nkk") || Catch::Contains("train.learning_rat"));
  const std::string msg2 =
      message_of([&] { load<Config>("configs/default.yaml", {"model.dparf.nkk=3"}); });
  CHECK_THAT(msg2, Catch::Contains("unknown config key 'model.dparf.nkk'"));
  CHECK_THAT(msg2, Catch::Contains("did you mean 'model.dparf.nk'"));
}

TEST_CASE("a retired key is ignored with one warning naming it, and is no key any more",
          "[config]") {
  // model.exact_shortcuts, model.readout_windows and model.encoder.fast_sampling chose how the
  // network was evaluated, never what it computes: configs and runs written with them still load.
  const fs::path dir = th::test::scratch_dir("config_retired");
  write_file(dir, "old.yaml",
             "parent: " + fs::absolute("configs/default.yaml").string() +
                 "\nmodel:\n  exact_shortcuts: false\n  readout_windows: true\n"
                 "  encoder:\n    fast_sampling: false\n");
  std::ostringstream captured;
  auto sink = std::make_shared<spdlog::sinks::ostream_sink_mt>(captured);
  spdlog::default_logger()->sinks().push_back(sink);
  Config c;
  const std::string error = message_of([&] { c = load<Config>(dir / "old.yaml"); });
  spdlog::default_logger()->sinks().pop_back();
  CHECK(error == "<no error>");
  const std::string log = captured.str();
  for (const char* key :
       {"'model.exact_shortcuts'", "'model.readout_windows'", "'model.encoder.fast_sampling'"}) {
    INFO(key);
    size_t count = 0;
    for (size_t at = log.find(key); at != std::string::npos; at = log.find(key, at + 1)) ++count;
    CHECK(count == 1);
  }
  CHECK_THAT(log, Catch::Contains("no longer read and is ignored"));
  // Not written back, not listed, and a config without them says nothing.
  const auto tree = to_tree(c);
  CHECK_FALSE(tree["model"]["exact_shortcuts"].IsDefined());
  CHECK_FALSE(tree["model"]["encoder"]["fast_sampling"].IsDefined());
  for (const auto& info : keys<Config>())
    CHECK(info.key.find("exact_shortcuts") == std::string::npos);
  std::ostringstream quiet;
  auto quiet_sink = std::make_shared<spdlog::sinks::ostream_sink_mt>(quiet);
  spdlog::default_logger()->sinks().push_back(quiet_sink);
  load<Config>("configs/default.yaml");
  spdlog::default_logger()->sinks().pop_back();
  CHECK(quiet.str().find("no longer read") == std::string::npos);
}

TEST_CASE("an override of an unknown key or section fails naming it", "[config]") {
  CHECK_THAT(message_of([] { load<Config>("configs/default.yaml", {"trian.lr=1"}); }),
             Catch::Contains("unknown config key 'trian'"));
  CHECK_THAT(message_of([] { load<Config>("configs/default.yaml", {"train.lr.x=1"}); }),
             Catch::Contains("'lr' is a value, not a section"));
  CHECK_THAT(message_of([] { load<Config>("configs/default.yaml", {"train.lr"}); }),
             Catch::Contains("must look like key.sub.key=value"));
}

TEST_CASE("a value of the wrong type fails naming key, expected type and value", "[config]") {
  CHECK_THAT(message_of([] { load<Config>("configs/default.yaml", {"train.epochs=many"}); }),
             Catch::Contains("config key 'train.epochs' must be an integer, got 'many'"));
  CHECK_THAT(message_of([] { load<Config>("configs/default.yaml", {"train.epochs=2.5"}); }),
             Catch::Contains("train.epochs"));
  CHECK_THAT(message_of([] { load<Config>("configs/default.yaml", {"data.patch=3"}); }),
             Catch::Contains("config key 'data.patch' must be a section"));
  CHECK_THAT(message_of([] { load<Config>("configs/default.yaml", {"data.jitter.hue=0.5"}); }),
             Catch::Contains("config key 'data.jitter.hue' must be a list"));
  CHECK_THAT(message_of([] { load<Config>("configs/default.yaml", {"device=gpu"}); }),
             Catch::Contains("'gpu' is not one of {auto, cpu, cuda}"));
}

TEST_CASE("integers are decimal: a leading zero is not octal, hexadecimal is refused", "[config]") {
  CHECK(load<Config>("configs/default.yaml", {"eval.limit=010"}).eval.limit == 10);
  CHECK(load<Config>("configs/default.yaml", {"eval.limit=+7"}).eval.limit == 7);
  CHECK(load<Config>("configs/default.yaml", {"render.samples=0064"}).render.samples == 64);
  CHECK_THAT(message_of([] { load<Config>("configs/default.yaml", {"eval.limit=0x10"}); }),
             Catch::Contains("config key 'eval.limit' must be an integer, got '0x10'"));
  CHECK_THAT(message_of([] { load<Config>("configs/default.yaml", {"eval.limit=99999999999"}); }),
             Catch::Contains("config key 'eval.limit' must be an integer, got '99999999999'"));
  CHECK(decimal_integer("-12") == -12);
  CHECK(decimal_integer("0") == 0);
  for (const char* text :
       {"", "+", "-", "+-1", " 7", "7 ", "1e3", "0x10", "0b1", "1.0", "99999999999999999999"})
    CHECK_FALSE(decimal_integer(text).has_value());
}

TEST_CASE("incompatible switches are refused with a reason", "[config]") {
  CHECK_THAT(message_of([] {
               load<Config>("configs/default.yaml",
                            {"model.fdi.appearance=false", "model.fdi.human=false"});
             }),
             Catch::Contains("at least one of the two branches"));
  CHECK_THAT(message_of([] {
               load<Config>("configs/default.yaml", {"model.grouping.kind=observation_grid"});
             }),
             Catch::Contains("transhe.position"));
  CHECK_THAT(message_of([] { load<Config>("configs/default.yaml", {"model.dparf.nk=0"}); }),
             Catch::Contains("model.dparf.nk"));
}

TEST_CASE("missing files and inheritance cycles are reported with the file name", "[config]") {
  const fs::path dir = th::test::scratch_dir("config_cycle");
  write_file(dir, "a.yaml", "parent: b.yaml\n");
  write_file(dir, "b.yaml", "parent: a.yaml\n");
  CHECK_THAT(message_of([&] { load<Config>(dir / "a.yaml"); }),
             Catch::Contains("inheritance cycle"));
  CHECK_THAT(message_of([&] { load<Config>(dir / "nope.yaml"); }),
             Catch::Contains("nope.yaml' does not exist"));
  write_file(dir, "bad.yaml", "train: [1, 2\n");
  CHECK_THAT(message_of([&] { load<Config>(dir / "bad.yaml"); }),
             Catch::Contains("YAML error at line"));
}

TEST_CASE("keys that are not names and self-referring or exploding aliases are refused",
          "[config]") {
  const fs::path dir = th::test::scratch_dir("config_graph");
  // Found by fuzz/config_fuzz: a YAML::BadConversion escaped, a stack overflow, a hang.
  write_file(dir, "list_key.yaml", "? [a, b]\n: 1\n");
  CHECK_THAT(message_of([&] { load<Config>(dir / "list_key.yaml"); }),
             Catch::Contains("list_key.yaml'") && Catch::Contains("is not a plain name"));
  write_file(dir, "cycle.yaml", "train: &x {lr: *x}\n");
  CHECK_THAT(message_of([&] { load<Config>(dir / "cycle.yaml"); }),
             Catch::Contains("cycle.yaml'") && Catch::Contains("'train.lr' contains itself"));
  std::string doubling = "l0: &a0 {x: 1, y: 2}\n";  // 2^40 values once the aliases expand
  for (int i = 1; i <= 40; ++i)
    doubling += "l" + std::to_string(i) + ": &a" + std::to_string(i) + " {p: *a" +
                std::to_string(i - 1) + ", q: *a" + std::to_string(i - 1) + "}\n";
  write_file(dir, "doubling.yaml", doubling);
  CHECK_THAT(message_of([&] { load<Config>(dir / "doubling.yaml"); }),
             Catch::Contains("doubling.yaml'") && Catch::Contains("aliases repeat too much"));
  CHECK_THAT(message_of([] { load<Config>("configs/default.yaml", {"train.lr=&x [*x]"}); }),
             Catch::Contains("override 'train.lr=&x [*x]'") && Catch::Contains("contains itself"));
}

TEST_CASE("the resolved config written to disk loads back to the same values", "[config]") {
  const fs::path dir = th::test::scratch_dir("config_resolved");
  const Config c =
      load<Config>("configs/default.yaml", {"train.lr=0.123", "model.fdi.raw_rgb=false"});
  write_yaml(dir / "config.yaml", to_tree(c));
  const Config back = load<Config>(dir / "config.yaml");
  CHECK(YAML::Dump(to_tree(back)) == YAML::Dump(to_tree(c)));
  CHECK(back.train.lr == Approx(0.123));
  CHECK_FALSE(back.model.fdi.raw_rgb);
}

TEST_CASE("every ablation row loads, validates and changes what its comment says",
          "[config][ablations]") {
  const YAML::Node full = to_tree(load<Config>("configs/ablations/full.yaml"));
  std::vector<std::string> full_keys;
  collect_keys(full, "", full_keys);
  int rows = 0;
  for (const auto& entry : fs::directory_iterator("configs/ablations")) {
    const std::string name = entry.path().stem().string();
    if (name.front() == '_' || name == "full") continue;
    INFO("configs/ablations/" << name << ".yaml");
    const YAML::Node row = to_tree(load<Config>(entry.path()));
    // The keys whose values differ from the full model's: what the row ablates.
    std::vector<std::string> changed;
    for (const auto& key : full_keys) {
      YAML::Node a = YAML::Clone(full), b = YAML::Clone(row);
      std::stringstream path(key);
      std::string part;
      while (std::getline(path, part, '.')) {
        a.reset(a[part]);
        b.reset(b[part]);
      }
      if (YAML::Dump(a) != YAML::Dump(b)) changed.push_back(key);
    }
    // The row's own file names exactly the changed keys (besides `parent`).
    std::vector<std::string> own;
    collect_keys(YAML::LoadFile(entry.path().string()), "", own);
    own.erase(std::remove(own.begin(), own.end(), "parent"), own.end());
    std::sort(own.begin(), own.end());
    std::sort(changed.begin(), changed.end());
    if (name == "samples_16")
      CHECK(changed.empty());  // the demo base renders 16 samples already
    else
      CHECK(changed == own);
    ++rows;
  }
  CHECK(rows >= 18);
}
