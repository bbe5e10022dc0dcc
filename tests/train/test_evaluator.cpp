#include <catch2/catch.hpp>

#include <fstream>
#include <sstream>

#include "eval/evaluator.hpp"
#include "train/trainer.hpp"
#include "support/test_env.hpp"

namespace fs = std::filesystem;

namespace {

std::string read_all(const fs::path& p) {
  std::ifstream in(p);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

}  // namespace

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
  CHECK_THAT(read_all(run / "eval_a" / "results.md"), Catch::Contains("| identity | 3 |"));
  size_t panels = 0;
  for (const auto& e : fs::directory_iterator(run / "eval_a" / "images")) panels += e.path().extension() == ".png";
  CHECK(panels == 3);
}
