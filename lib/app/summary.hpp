#pragma once
// The --dry-run summary: what the config names, built and counted.

#include "app/app.hpp"

namespace th::app {

// Logs the data, model and training set-up of the run. With `dry_run` it also proves that the
// run could start: the first sample of each setting is loaded (images, masks, cameras, body)
// and `checkpoint`, when named, is read into the model; any failure is the run's error (a
// plain summary only warns that the data is not available).
void print_summary(const RunContext& ctx, bool dry_run = false, const std::string& checkpoint = "");

// Loads sample 0 of the training setting as training does (patches included), so that what
// only the data can refuse (a patch larger than the image, a body outside the view) fails
// before a run folder is written.
void load_first_training_sample(const Config& config);

}  // namespace th::app
