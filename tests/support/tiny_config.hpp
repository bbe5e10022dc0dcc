#pragma once
// The tiny training configuration on the tiny synthetic dataset (tests/configs/tiny_train.yaml,
// data and k-means cache under the build tree's test_tmp), with more overrides on top.

#include <string>
#include <vector>

#include "core/config_io.hpp"
#include "support/test_env.hpp"

namespace th::test {

inline Config tiny_train_config(std::vector<std::string> overrides = {}) {
  const auto root = tiny_dataset();
  overrides.push_back("data.root=" + root.string());
  overrides.push_back("data.split_file=" + (root / "split.yaml").string());
  overrides.push_back("model.grouping.cache_dir=" + (root.parent_path() / "kmeans_cache").string());
  return config::load<Config>("tests/configs/tiny_train.yaml", overrides);
}

}  // namespace th::test
