#include "model/frame_cache.hpp"

#include <set>

namespace th::model {

void FrameGeometry::visit(const TensorVisitor& fn) {
  for (auto* t : {&K, &R, &T, &Rh, &Th}) fn(*t, nullptr);
}

void PixelReadouts::visit(const TensorVisitor& fn) {
  alpha.visit(fn);
  color.visit(fn);
}

void WindowReadouts::visit(const TensorVisitor& fn) {
  for (auto& level : enc.levels) fn(level, nullptr);
  fn(enc.images, nullptr);
  alpha.visit(fn);
  color.visit(fn);
}

void TokenTableStage::visit(const TensorVisitor& fn) {
  fn(frames.origins, nullptr);
  fn(frames.rotations, nullptr);
  fn(table, &table_grad_sink);
}

void SPCStage::visit(const TensorVisitor& fn) {
  for (auto* t : {&grid, &lo, &extent}) fn(*t, nullptr);
}

void FoldedWeights::visit(const TensorVisitor& fn) {
  for (auto* t : {&fdi.w0, &fdi.b0, &fdi.w1, &fdi.b1, &heads.e_weight, &heads.e_bias,
                  &heads.readout_weight, &heads.readout_bias})
    fn(*t, nullptr);
}

void FrameCache::visit(const TensorVisitor& fn) {
  geometry.visit(fn);
  std::visit([&](auto& stage) { stage.visit(fn); }, pixels);
  std::visit([&](auto& stage) { stage.visit(fn); }, human);
  network.visit(fn);
}

double FrameCache::nbytes() const {
  std::set<const void*> seen;
  double total = 0;
  const_cast<FrameCache*>(this)->visit([&](torch::Tensor& t, torch::Tensor*) {
    if (t.defined() && seen.insert(t.data_ptr()).second) total += double(t.nbytes());
  });
  return total;
}

}  // namespace th::model
