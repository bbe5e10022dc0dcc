#pragma once
// Periodic validation during training: render a few test views, log their PSNR, keep the
// images, and warn when the model has collapsed (renders all black).

#include <filesystem>

#include "core/config.hpp"
#include "data/dataset.hpp"
#include "model/transhuman.hpp"
#include "pipeline/jsonl.hpp"
#include "pipeline/pipeline.hpp"

namespace th::train {

// Returns the mean PSNR of the rendered views; writes <dir>/epoch_<e>_<k>.png panels.
double validate(model::TransHumanImpl& model, const Config& config, const data::Dataset& val_set,
                pipeline::Tokens& tokens, const torch::Tensor& canonical,
                const torch::Device& device, const std::filesystem::path& dir, int epoch,
                pipeline::JsonlWriter& log, int64_t step);

}  // namespace th::train
