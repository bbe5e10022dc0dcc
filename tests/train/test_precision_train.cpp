// Training in bf16: the run's checkpoint holds fp32 weights, loads into an fp32 model and
// evaluates in fp32 as an fp32-trained one does.
#include <torch/torch.h>

#include <catch2/catch.hpp>
#include <cmath>

#include "eval/evaluator.hpp"
#include "model/transhuman.hpp"
#include "pipeline/checkpoint.hpp"
#include "support/test_env.hpp"
#include "support/tiny_config.hpp"
#include "train/trainer.hpp"

namespace fs = std::filesystem;

TEST_CASE("a bf16-trained checkpoint holds fp32 weights and evaluates in fp32",
          "[train][precision]") {
  torch::set_num_threads(1);
  const auto bf16 = th::test::tiny_train_config({"train.val_views=0", "precision=bf16"});
  const fs::path run = th::test::scratch_dir("bf16_train");
  const auto summary = th::train::train(bf16, torch::kCPU, {run, false, 2});
  REQUIRE(summary.steps == 2);
  CHECK(std::isfinite(summary.last_loss));

  const auto fp32 =
      th::test::tiny_train_config({"precision=fp32", "eval.limit=2", "eval.save_images=false"});
  th::model::TransHuman model(fp32.model);
  th::pipeline::load_weights(*model, run / "checkpoints" / "latest.pt");
  int64_t tensors = 0;
  for (const auto& p : model->named_parameters()) {
    CAPTURE(p.key());
    CHECK(p.value().scalar_type() == torch::kFloat);
    CHECK(torch::isfinite(p.value()).all().item<bool>());
    ++tensors;
  }
  CHECK(tensors > 0);
  const fs::path out = th::test::scratch_dir("bf16_train_eval");
  fs::create_directories(out);
  const auto s = th::eval::evaluate(fp32, torch::kCPU, run / "checkpoints" / "latest.pt", out);
  CHECK(s.images == 2);
  CHECK(std::isfinite(s.psnr));
  CHECK(s.psnr > 5);  // an image, not noise or NaN
  // And back: the same checkpoint evaluates in bf16 within 0.5 dB of fp32 after two steps.
  const auto back =
      th::test::tiny_train_config({"precision=bf16", "eval.limit=2", "eval.save_images=false"});
  const fs::path out16 = th::test::scratch_dir("bf16_train_eval16");
  fs::create_directories(out16);
  const auto s16 = th::eval::evaluate(back, torch::kCPU, run / "checkpoints" / "latest.pt", out16);
  CHECK(std::abs(s16.psnr - s.psnr) < 0.5);
}
