#include "train/schedule.hpp"

#include <algorithm>
#include <cmath>

namespace th::train {

double learning_rate(const TrainConfig& c, int epoch) {
  if (epoch < c.warmup_epochs) return c.lr * double(epoch + 1) / double(c.warmup_epochs);
  const double span = std::max(1, c.epochs - c.warmup_epochs);
  const double progress = std::min(1.0, double(epoch - c.warmup_epochs) / span);
  return c.min_lr + 0.5 * (c.lr - c.min_lr) * (1.0 + std::cos(M_PI * progress));
}

}  // namespace th::train
