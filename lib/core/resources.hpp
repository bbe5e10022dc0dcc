#pragma once
// Resource requests checked before work starts (a render or mesh of absurd size must fail in a
// second with what it would have cost, not after filling memory): an estimate of peak memory
// and of the points the network evaluates, printed, and refused above the `max_memory_gb` key.

#include <cstdint>
#include <string>

namespace th::resources {

// Physical memory of this machine in bytes (0 when unknown).
int64_t physical_memory_bytes();

// The bound in bytes: `max_memory_gb` GiB, or 3/4 of physical memory when it is 0.
double memory_limit_bytes(double max_memory_gb);

// Bytes of working memory per point of a network chunk (features of every reference view,
// the FDI and head activations): an upper bound of the peak tensor memory of the 512x512
// render in bench/results/model.md at chunk_points 4096.
constexpr double kBytesPerChunkPoint = 200.0 * 1024;
// Network samples per second per CPU thread in a progressive render, for the time estimate:
// the rate of the 512x512 render in bench/results/model.md, rounded.
constexpr double kSamplesPerSecondPerThread = 70000;

struct Estimate {
  std::string what;    // "render 512 x 512 x 36 frames"
  double bytes = 0;    // peak working memory
  double samples = 0;  // upper bound of network samples (0: not known)
  int threads = 1;     // CPU threads for the time estimate (0: not on the CPU)
};

// Logs the estimate (memory, samples, time) and throws th::Error when the memory is above the
// limit, naming the estimate and the key that raises it.
void check(const Estimate& estimate, double max_memory_gb);

// "1.2 GiB" / "340 MiB".
std::string bytes_text(double bytes);

}  // namespace th::resources
