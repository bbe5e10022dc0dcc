#include <spdlog/sinks/ostream_sink.h>
#include <spdlog/spdlog.h>
#include <torch/torch.h>

#include <catch2/catch.hpp>
#include <fstream>
#include <sstream>

#include "body/smpl.hpp"
#include "core/error.hpp"
#include "data/dataset.hpp"
#include "model/transhuman.hpp"
#include "pipeline/checkpoint.hpp"
#include "support/test_env.hpp"
#include "support/tiny_config.hpp"
#include "train/schedule.hpp"
#include "train/trainer.hpp"
#include "train/validation.hpp"

namespace fs = std::filesystem;

namespace {

th::Config tiny_config(std::vector<std::string> overrides = {}) {
  return th::test::tiny_train_config(std::move(overrides));
}

std::map<std::string, torch::Tensor> weights_of(const fs::path& checkpoint, const th::Config& c) {
  th::model::TransHuman model(c.model);
  th::pipeline::load_weights(*model, checkpoint);
  std::map<std::string, torch::Tensor> out;
  for (const auto& p : model->named_parameters()) out[p.key()] = p.value().clone();
  for (const auto& b : model->named_buffers()) out[b.key()] = b.value().clone();
  return out;
}

}  // namespace

TEST_CASE("the schedule warms up linearly, then follows a cosine to min_lr", "[train]") {
  th::TrainConfig c;  // 3000 epochs, 300 warm-up, 7e-4 -> 1e-6
  CHECK(th::train::learning_rate(c, 0) == Approx(7e-4 / 300));
  CHECK(th::train::learning_rate(c, 149) == Approx(7e-4 * 150 / 300));
  CHECK(th::train::learning_rate(c, 300) == Approx(7e-4));
  CHECK(th::train::learning_rate(c, 1650) == Approx(1e-6 + 0.5 * (7e-4 - 1e-6)));
  CHECK(th::train::learning_rate(c, 3000) == Approx(1e-6));
}

TEST_CASE("a run stopped and resumed ends with the same weights as one that was not",
          "[train][resume]") {
  torch::set_num_threads(1);
  const auto c = tiny_config({"train.val_views=0"});
  const fs::path a = th::test::scratch_dir("resume_straight"),
                 b = th::test::scratch_dir("resume_split");
  const auto straight = th::train::train(c, torch::kCPU, {a, false, 4});
  CHECK(straight.steps == 4);
  const auto first = th::train::train(c, torch::kCPU, {b, false, 2});  // stops inside epoch 0
  CHECK(first.steps == 2);
  const auto resumed = th::train::train(c, torch::kCPU, {b, true, 4});
  CHECK(resumed.steps == 4);
  const auto wa = weights_of(a / "checkpoints" / "latest.pt", c);
  const auto wb = weights_of(b / "checkpoints" / "latest.pt", c);
  REQUIRE(wa.size() == wb.size());
  size_t differing = 0;
  for (const auto& [name, t] : wa) differing += !torch::equal(t, wb.at(name));
  CHECK(differing == 0);
  // And training changed the weights (the comparison is not between two untouched models).
  torch::manual_seed(uint64_t(c.seed));
  th::model::TransHuman fresh(c.model);
  size_t changed = 0;
  for (const auto& p : fresh->named_parameters())
    changed += !torch::equal(p.value(), wa.at(p.key()));
  CHECK(changed > 10);
}

TEST_CASE("keeping the per-point graphs trains the same weights as recomputing them, bit for bit",
          "[train][recompute]") {
  torch::set_num_threads(1);
  // Chunks of 256 of the 1,024 samples per step: several chunks, run in the same order.
  for (const char* skip : {"false", "true"}) {
    CAPTURE(skip);
    std::map<std::string, std::map<std::string, torch::Tensor>> weights;
    for (const char* mode : {"always", "never", "auto"}) {
      const auto c = tiny_config({"train.val_views=0", "render.train_chunk_points=256",
                                  std::string("render.train_recompute=") + mode,
                                  std::string("train.skip_far_points=") + skip});
      const fs::path run = th::test::scratch_dir(std::string("recompute_") + mode + "_" + skip);
      CHECK(th::train::train(c, torch::kCPU, {run, false, 3}).steps == 3);
      weights[mode] = weights_of(run / "checkpoints" / "latest.pt", c);
    }
    for (const char* mode : {"never", "auto"}) {
      CAPTURE(mode);
      REQUIRE(weights[mode].size() == weights["always"].size());
      size_t differing = 0;
      for (const auto& [name, t] : weights["always"])
        differing += !torch::equal(t, weights[mode].at(name));
      CHECK(differing == 0);
    }
  }
}

TEST_CASE("the run directory holds metrics, checkpoints, validation images and the curve",
          "[train]") {
  const auto c = tiny_config();
  const fs::path run = th::test::scratch_dir("train_outputs");
  const auto s = th::train::train(c, torch::kCPU, {run, false, -1});
  CHECK(s.steps == 6);
  CHECK(fs::exists(run / "checkpoints" / "latest.pt"));
  CHECK(fs::exists(run / "checkpoints" / "epoch_0001.pt"));
  CHECK(fs::exists(run / "checkpoints" / "epoch_0002.pt"));
  CHECK(fs::exists(run / "val" / "epoch_0002_0.png"));
  CHECK(fs::exists(run / "training_curve.png"));
  std::ifstream in(run / "metrics.jsonl");
  std::string line;
  std::getline(in, line);
  for (const char* key : {"\"step\": 1", "\"epoch\": 0", "\"lr\"", "\"loss\"", "\"psnr\"",
                          "\"time_per_step\"", "\"rays_per_second\""})
    CHECK_THAT(line, Catch::Contains(key));
  // No temporary checkpoint is left behind.
  for (const auto& e : fs::directory_iterator(run / "checkpoints"))
    CHECK(e.path().extension() != ".tmp");
}

TEST_CASE("checkpoint and validation intervals of 0 mean: only after the last epoch", "[train]") {
  const auto c = tiny_config({"train.save_every_epochs=0", "train.val_every_epochs=0"});
  const fs::path run = th::test::scratch_dir("train_every_zero");
  const auto s = th::train::train(c, torch::kCPU, {run, false, -1});
  CHECK(s.steps == 6);
  CHECK(fs::exists(run / "checkpoints" / "latest.pt"));
  CHECK(fs::exists(run / "checkpoints" / "epoch_0002.pt"));  // the last epoch
  CHECK_FALSE(fs::exists(run / "checkpoints" / "epoch_0001.pt"));
  CHECK(fs::exists(run / "val" / "epoch_0002_0.png"));
  CHECK_FALSE(fs::exists(run / "val" / "epoch_0001_0.png"));
  CHECK_THROWS_WITH(tiny_config({"train.val_every_epochs=-1"}),
                    Catch::Contains("train.val_every_epochs"));
}

TEST_CASE("a NaN loss stops the run naming the step and the last good checkpoint", "[train]") {
  // An absurd learning rate overflows the weights after the first update.
  const auto c = tiny_config({"train.lr=1e30", "train.warmup_epochs=0", "train.val_views=0"});
  const fs::path run = th::test::scratch_dir("train_nan");
  CHECK_THROWS_WITH(th::train::train(c, torch::kCPU, {run, false, -1}),
                    Catch::Contains("the loss became") && Catch::Contains("at step") &&
                        Catch::Contains("last good checkpoint"));
}

TEST_CASE("a collapsed model's empty validation renders are reported", "[train]") {
  std::ostringstream captured;
  auto sink = std::make_shared<spdlog::sinks::ostream_sink_mt>(captured);
  const auto c = tiny_config();
  const auto smpl = th::data::load_body_model(c.data);
  const auto val = std::make_shared<const th::data::Dataset>(c.data, c.data.test_setting,
                                                             th::data::Dataset::Mode::Test, smpl);
  th::model::TransHuman model(c.model);
  {
    // The failure users of the reference code report: density negative everywhere.
    torch::NoGradGuard g;
    model->heads->alpha_fc->bias.fill_(-100.0f);
  }
  th::pipeline::Tokens tokens(*model, smpl->v_template);
  const fs::path dir = th::test::scratch_dir("train_collapse");
  th::pipeline::JsonlWriter log(dir / "metrics.jsonl");
  spdlog::default_logger()->sinks().push_back(sink);
  th::train::validate(model, c, val, tokens, smpl->v_template, torch::kCPU, dir, 1, log, 0);
  spdlog::default_logger()->sinks().pop_back();
  CHECK_THAT(captured.str(), Catch::Contains("collapsed") && Catch::Contains("Try:"));
}

TEST_CASE("validation from bakes names its renderer and its time in the metrics", "[train][bake]") {
  const auto exact = tiny_config(),
             baked = tiny_config({"train.val_renderer=baked", "eval.bake_voxel=0.04"});
  const auto smpl = th::data::load_body_model(exact.data);
  const auto val = std::make_shared<const th::data::Dataset>(exact.data, exact.data.test_setting,
                                                             th::data::Dataset::Mode::Test, smpl);
  th::model::TransHuman model(exact.model);
  th::pipeline::Tokens tokens(*model, smpl->v_template);
  const fs::path dir = th::test::scratch_dir("train_val_baked");
  {
    th::pipeline::JsonlWriter log(dir / "metrics.jsonl");
    th::train::validate(model, exact, val, tokens, smpl->v_template, torch::kCPU, dir, 1, log, 5);
    th::train::validate(model, baked, val, tokens, smpl->v_template, torch::kCPU, dir, 2, log, 10);
  }
  CHECK(model->is_training());  // left as training found it
  std::ifstream in(dir / "metrics.jsonl");
  std::string first, second;
  std::getline(in, first);
  std::getline(in, second);
  CHECK_THAT(first, Catch::Contains("\"val_renderer\": \"exact\""));
  CHECK_THAT(second, Catch::Contains("\"val_renderer\": \"baked 4 cm\"") &&
                         Catch::Contains("\"val_psnr\": ") && Catch::Contains("\"val_seconds\""));
  CHECK(fs::exists(dir / "epoch_0002_0.png"));
}
