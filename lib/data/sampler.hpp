#pragma once
// Which sample each rank trains on (METHOD 5, data-parallel): every epoch is a seeded permutation
// of the dataset, the same on every rank; iteration `it` of an epoch takes the global positions
// it*W .. it*W + W-1 of that permutation (W ranks), rank r the position it*W + r, cycling through
// the permutation when an epoch needs more samples than there are. A sample's randomness
// (reference views, jitter, patches) is drawn from a seed of (run seed, epoch, position), so a
// rank's samples do not depend on the loading thread or on the other ranks. With W = 1 this is
// the single-process order.

#include <cstdint>
#include <vector>

namespace th::data {

// SplitMix64 finaliser: decorrelated seeds from (run seed, epoch, iteration).
inline uint64_t mix_seed(uint64_t x) {
  x += 0x9E3779B97F4A7C15ull;
  x = (x ^ (x >> 30)) * 0xBF58476D1CE4E5B9ull;
  x = (x ^ (x >> 27)) * 0x94D049BB133111EBull;
  return x ^ (x >> 31);
}

class ShardedSampler {
 public:
  // dataset_size > 0; world_size: samples per iteration over all ranks (the global batch).
  ShardedSampler(size_t dataset_size, uint64_t seed, int world_size);

  struct Draw {
    std::vector<size_t> order;    // dataset indices
    std::vector<uint64_t> seeds;  // one per index, for Dataset::load
  };
  // The samples of the global ranks `ranks` for iterations [first, last) of `epoch`, iteration by
  // iteration and, within one, in the order of `ranks`.
  Draw draw(int epoch, int first, int last, const std::vector<int>& ranks) const;

  // The permutation of `epoch` (dataset indices).
  std::vector<size_t> permutation(int epoch) const;

 private:
  size_t size_;
  uint64_t seed_;
  int world_;
};

}  // namespace th::data
