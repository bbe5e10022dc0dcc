#pragma once
// Periodic validation during training: render a few test views, log their PSNR, keep the
// images, and warn when the model has collapsed (renders all black). train.val_renderer says
// how the views are rendered: exact, or from bakes of their frames (eval.bake_voxel); the
// metrics line names it (val_renderer), and the training curve with it.

#include <filesystem>

#include "core/config.hpp"
#include "data/dataset.hpp"
#include "model/transhuman.hpp"
#include "pipeline/jsonl.hpp"
#include "pipeline/pipeline.hpp"

namespace th::train {

// Returns the mean PSNR of the rendered views; writes <dir>/epoch_<e>_<k>.png panels.
double validate(model::TransHuman model, const Config& config,
                const std::shared_ptr<const data::Dataset>& val_set, pipeline::Tokens& tokens,
                const torch::Tensor& canonical, const torch::Device& device,
                const std::filesystem::path& dir, int epoch, pipeline::JsonlWriter& log,
                int64_t step);

}  // namespace th::train
