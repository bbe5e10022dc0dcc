#pragma once
// The --dry-run summary: what the config names, built and counted.

#include "app/app.hpp"

namespace th::app {

// Logs the data, model and training set-up of the run.
void print_summary(const RunContext& ctx);

}  // namespace th::app
