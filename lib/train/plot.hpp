#pragma once
// The training curve as a PNG: loss and PSNR of the training batches (and validation PSNR) over
// steps, read back from the run's metrics.jsonl.

#include <filesystem>

namespace th::train {

// Reads <metrics.jsonl> and writes the plot to `png`. Returns false (and writes nothing) when
// the file has fewer than two logged steps.
bool plot_training_curve(const std::filesystem::path& metrics_jsonl,
                         const std::filesystem::path& png);

}  // namespace th::train
