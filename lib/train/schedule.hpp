#pragma once
// Learning-rate schedule (METHOD 5): per epoch, linear warm-up from 0 over warmup_epochs, then a
// cosine from lr down to min_lr at the last epoch.

#include "core/config.hpp"

namespace th::train {

// Learning rate for `epoch` (0-based). Epoch 0 of the warm-up has lr * 1 / warmup_epochs, so
// that no epoch trains at lr 0 (the reference's off-by-one at epochs 0-1 is not copied).
double learning_rate(const TrainConfig& config, int epoch);

}  // namespace th::train
