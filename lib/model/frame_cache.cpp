#include "model/frame_cache.hpp"

#include <set>

namespace th::model {

void FrameCache::visit(const std::function<void(torch::Tensor&, torch::Tensor*)>& fn) {
  auto& g = geometry;
  for (auto* t : {&g.K, &g.R, &g.T, &g.Rh, &g.Th}) fn(*t, nullptr);
  auto& px = pixels;
  fn(px.pixel, nullptr);
  for (auto& level : px.levels) fn(level, nullptr);
  fn(px.images, nullptr);
  for (auto* r : {&px.alpha, &px.color}) {
    fn(r->table, &r->table_grad_sink);
    fn(r->image_table, nullptr);
    fn(r->image_weight, nullptr);
    fn(r->bias, nullptr);
    fn(r->window_table, nullptr);  // (r->weight and layer_bias are the layer's parameters)
  }
  auto& h = human;
  fn(h.frames.origins, nullptr);
  fn(h.frames.rotations, nullptr);
  fn(h.tokens, nullptr);
  fn(h.table, &h.table_grad_sink);
  for (auto* t : {&h.grid, &h.lo, &h.extent}) fn(*t, nullptr);
  auto& f = folded;
  for (auto* t : {&f.fdi.w0, &f.fdi.b0, &f.fdi.w1, &f.fdi.b1, &f.heads.e_weight, &f.heads.e_bias,
                  &f.heads.readout_weight, &f.heads.readout_bias})
    fn(*t, nullptr);
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
