#pragma once
// The tiny network trained until it has surfaces (CTest fixture `trained_tiny`,
// tests/configs/tiny_surface.yaml) and the frames of its identity test set.

#include <torch/torch.h>

#include <catch2/catch.hpp>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include "body/smpl.hpp"
#include "core/config_io.hpp"
#include "data/dataset.hpp"
#include "model/transhuman.hpp"
#include "pipeline/checkpoint.hpp"
#include "pipeline/pipeline.hpp"
#include "support/test_env.hpp"

namespace th::test {

inline Config surface_config(std::vector<std::string> overrides = {}) {
  const auto root = tiny_dataset();
  overrides.insert(
      overrides.begin(),
      {"data.root=" + root.string(), "data.split_file=" + (root / "split.yaml").string(),
       "model.grouping.cache_dir=" + (root.parent_path() / "kmeans_cache").string(),
       "eval.setting=identity", "eval.save_images=false"});
  return config::load<Config>("tests/configs/tiny_surface.yaml", overrides);
}

inline std::filesystem::path trained_checkpoint() {
  const auto path = test_tmp_root() / "trained_tiny" / "checkpoints" / "latest.pt";
  REQUIRE(std::filesystem::exists(path));  // made by the CTest fixture trained_tiny_checkpoint
  return path;
}

// The trained model (fp32 products through BLAS unless set otherwise) and the test frames.
struct Frames {
  Config config;
  model::TransHuman model{nullptr};
  std::shared_ptr<const data::Dataset> dataset;
  torch::Tensor canonical;
  std::unique_ptr<pipeline::Tokens> tokens;

  explicit Frames(Config c) : config(std::move(c)) {
    model = model::TransHuman(config.model);
    pipeline::load_weights(*model, trained_checkpoint());
    model->eval();
    const auto smpl = data::load_body_model(config.data);
    dataset = std::make_shared<const data::Dataset>(config.data, "identity",
                                                    data::Dataset::Mode::Test, smpl);
    canonical = smpl->v_template;
    tokens = std::make_unique<pipeline::Tokens>(*model, smpl->v_template);
  }
  model::FrameInputs inputs(const data::Sample& s) {
    return pipeline::frame_inputs(s, canonical, tokens->labels(s.body), torch::kCPU);
  }
};

}  // namespace th::test
