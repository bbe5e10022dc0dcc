#include "data/sampler.hpp"

#include <torch/types.h>

#include <algorithm>
#include <numeric>
#include <random>

namespace th::data {

ShardedSampler::ShardedSampler(size_t dataset_size, uint64_t seed, int world_size)
    : size_(dataset_size), seed_(seed), world_(world_size) {
  TORCH_CHECK(size_ > 0, "ShardedSampler: empty dataset");
  TORCH_CHECK(world_ >= 1, "ShardedSampler: world size ", world_, " < 1");
}

std::vector<size_t> ShardedSampler::permutation(int epoch) const {
  std::mt19937_64 rng(mix_seed(seed_ ^ mix_seed(uint64_t(epoch))));
  std::vector<size_t> perm(size_);
  std::iota(perm.begin(), perm.end(), 0);
  std::shuffle(perm.begin(), perm.end(), rng);
  return perm;
}

ShardedSampler::Draw ShardedSampler::draw(int epoch, int first, int last,
                                          const std::vector<int>& ranks) const {
  const auto perm = permutation(epoch);
  Draw d;
  for (int it = first; it < last; ++it)
    for (int r : ranks) {
      TORCH_CHECK(r >= 0 && r < world_, "ShardedSampler: rank ", r, " outside [0, ", world_, ")");
      const uint64_t position = uint64_t(it) * uint64_t(world_) + uint64_t(r);
      d.order.push_back(perm[position % perm.size()]);
      d.seeds.push_back(mix_seed(seed_ * 1000003ull + uint64_t(epoch) * 7919ull + position));
    }
  return d;
}

}  // namespace th::data
