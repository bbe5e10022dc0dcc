#pragma once
// The one chunk loop: work over n items in consecutive ranges of at most `chunk` items, so that
// memory is bounded by a chunk whatever n is. Every chunked evaluation of the project (the
// network over points, rays over batches, densities over grids) goes through it.

#include <torch/types.h>

#include <algorithm>
#include <cstdint>
#include <vector>

namespace th::render {

// Calls fn(begin, end) for [0, n) in ranges of at most `chunk` (chunk >= 1), in order.
template <class Fn>
void for_each_chunk(int64_t n, int64_t chunk, Fn&& fn) {
  TORCH_CHECK(chunk >= 1, "chunk size must be positive, got ", chunk);
  for (int64_t begin = 0; begin < n; begin += chunk) fn(begin, std::min(n, begin + chunk));
}

// The tensors fn(begin, end) of the chunks, concatenated along dimension 0 (n <= chunk, n = 0
// included: fn(0, n) as it is).
template <class Fn>
torch::Tensor cat_chunks(int64_t n, int64_t chunk, Fn&& fn) {
  if (n <= chunk) return fn(int64_t{0}, n);
  std::vector<torch::Tensor> parts;
  for_each_chunk(n, chunk, [&](int64_t b, int64_t e) { parts.push_back(fn(b, e)); });
  return torch::cat(parts);
}

}  // namespace th::render
