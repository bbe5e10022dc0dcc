#include <catch2/catch.hpp>
#include <fstream>
#include <sstream>

#include "body/grouping.hpp"
#include "body/smpl.hpp"
#include "data/dataset.hpp"
#include "eval/evaluator.hpp"
#include "model/transhuman.hpp"
#include "pipeline/checkpoint.hpp"
#include "support/test_env.hpp"
#include "train/trainer.hpp"

namespace fs = std::filesystem;

namespace {

std::string read_all(const fs::path& p) {
  std::ifstream in(p);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

// per_image.csv without its timing column (seconds): the rows that must not change.
std::string scores_of(const fs::path& csv) {
  std::stringstream in(read_all(csv)), out;
  for (std::string line; std::getline(in, line);) {
    std::stringstream cells(line);
    int column = 0;
    for (std::string cell; std::getline(cells, cell, ','); ++column)
      if (column != 6) out << cell << ',';
    out << '\n';
  }
  return out.str();
}

}  // namespace

TEST_CASE("a checkpoint evaluates with its own token groups: no k-means cache, another seed",
          "[eval][tokens]") {
  const auto root = th::test::tiny_dataset();
  const fs::path run = th::test::scratch_dir("eval_token_groups");
  auto config = [&](const fs::path& cache, std::vector<std::string> more) {
    more.insert(
        more.end(),
        {"data.root=" + root.string(), "data.split_file=" + (root / "split.yaml").string(),
         "model.grouping.cache_dir=" + cache.string(), "train.val_views=0", "eval.limit=3"});
    return th::config::load<th::Config>("tests/configs/tiny_train.yaml", more);
  };
  const auto c = config(run / "cache", {});
  const auto trained = th::train::train(c, torch::kCPU, {run, false, 2});
  th::eval::evaluate(c, torch::kCPU, trained.checkpoint, run / "eval_a");

  // An empty cache and another seed: without warn, refused by name.
  const fs::path empty_cache = run / "empty_cache";
  const auto other = config(empty_cache, {"model.grouping.seed=5"});
  CHECK_THROWS_WITH(
      th::eval::evaluate(other, torch::kCPU, trained.checkpoint, run / "eval_refused"),
      Catch::Contains("model.grouping.seed: checkpoint 0, config 5"));
  // With warn: the checkpoint's groups, so the same rows; the k-means never ran.
  const auto warned = config(empty_cache, {"model.grouping.seed=5", "eval.model_mismatch=warn"});
  th::eval::evaluate(warned, torch::kCPU, trained.checkpoint, run / "eval_b");
  CHECK(scores_of(run / "eval_a" / "per_image.csv") == scores_of(run / "eval_b" / "per_image.csv"));
  CHECK_FALSE(fs::exists(empty_cache));
  // Not vacuous: seed 5 groups this body otherwise than the checkpoint's groups.
  th::model::TransHuman model(c.model);
  th::pipeline::load_weights(*model, trained.checkpoint);
  const auto canonical = th::data::load_body_model(c.data)->v_template;
  CHECK_FALSE(torch::equal(th::body::kmeans(canonical, 24, 5), model->token_groups().labels));
}

TEST_CASE("evaluating a checkpoint twice gives identical numbers and all outputs", "[eval]") {
  const auto root = th::test::tiny_dataset();
  auto c = th::config::load<th::Config>(
      "tests/configs/tiny_train.yaml",
      {"data.root=" + root.string(), "data.split_file=" + (root / "split.yaml").string(),
       "model.grouping.cache_dir=" + (root.parent_path() / "kmeans_cache").string(),
       "train.val_views=0", "eval.limit=3"});
  const fs::path run = th::test::scratch_dir("eval_twice");
  const auto trained = th::train::train(c, torch::kCPU, {run, false, 2});
  const auto a = th::eval::evaluate(c, torch::kCPU, trained.checkpoint, run / "eval_a");
  const auto b = th::eval::evaluate(c, torch::kCPU, trained.checkpoint, run / "eval_b");
  CHECK(a.images == 3);
  CHECK(a.psnr == b.psnr);
  CHECK(a.ssim == b.ssim);
  CHECK_FALSE(a.lpips_available);  // no weights configured: reported as unavailable
  const auto csv_a = read_all(run / "eval_a" / "per_image.csv");
  // Timing columns differ between runs; the scores must not.
  auto scores = [](const std::string& csv) {
    std::stringstream in(csv), out;
    for (std::string line; std::getline(in, line);) {
      size_t comma = 0;
      for (int i = 0; i < 6 && comma != std::string::npos; ++i) comma = line.find(',', comma + 1);
      out << line.substr(0, comma) << '\n';
    }
    return out.str();
  };
  CHECK(scores(csv_a) == scores(read_all(run / "eval_b" / "per_image.csv")));
  CHECK(fs::exists(run / "eval_a" / "summary.json"));
  CHECK_THAT(read_all(run / "eval_a" / "results.md"), Catch::Contains("| identity | exact | 3 |"));
  size_t panels = 0;
  for (const auto& e : fs::directory_iterator(run / "eval_a" / "images"))
    panels += e.path().extension() == ".png";
  CHECK(panels == 3);

  // per_image.csv's point counts against an independent count: every sample of every in-box
  // ray (points), and those farther than render.cull_distance from all body vertices (culled).
  const th::data::Dataset ds(c.data, "identity", th::data::Dataset::Mode::Test,
                             th::data::load_body_model(c.data));
  std::stringstream rows(csv_a);
  std::string line;
  std::getline(rows, line);
  REQUIRE(
      line ==
      "human,frame,view,psnr,ssim,lpips,seconds,points,culled_points,evaluated_points,renderer");
  int checked = 0;
  while (std::getline(rows, line)) {
    std::vector<std::string> f;
    std::stringstream cells(line);
    for (std::string cell; std::getline(cells, cell, ',');) f.push_back(cell);
    REQUIRE(f.size() == 11);
    CHECK(f[10] == "exact");
    INFO(line);
    for (size_t i = 0; i < ds.size(); ++i) {
      const auto s = ds.load(i, 0);
      if (s.human != f[0] || s.frame != std::stoi(f[1]) || s.target_view != std::stoi(f[2]))
        continue;
      const int64_t S = c.render.samples;
      const auto t = torch::linspace(0, 1, S, torch::kFloat64);
      const auto near = s.near.to(torch::kFloat64).unsqueeze(1),
                 far = s.far.to(torch::kFloat64).unsqueeze(1);
      const auto z = near * (1 - t) + far * t;  // (R, S)
      const auto pts = s.ray_o.to(torch::kFloat64).unsqueeze(1) +
                       s.ray_d.to(torch::kFloat64).unsqueeze(1) * z.unsqueeze(2);
      const auto d = std::get<0>(
          torch::cdist(pts.reshape({-1, 3}), s.body.vertices.to(torch::kFloat64)).min(1));
      const int64_t points = s.ray_o.size(0) * S;
      const int64_t culled = (d > c.render.cull_distance).sum().item<int64_t>();
      const int64_t borderline = ((d - c.render.cull_distance).abs() < 1e-5).sum().item<int64_t>();
      CHECK(std::stoll(f[7]) == points);
      CHECK(std::abs(std::stoll(f[8]) - culled) <= borderline);
      CHECK(culled < points);
      // Evaluated: at most the kept points (early termination skips some of them).
      CHECK(std::stoll(f[9]) > 0);
      CHECK(std::stoll(f[9]) <= std::stoll(f[7]) - std::stoll(f[8]));
      ++checked;
    }
  }
  CHECK(checked == 3);
}
