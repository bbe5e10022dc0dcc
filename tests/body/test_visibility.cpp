#include <catch2/catch.hpp>
#include <cmath>

#include "body/visibility.hpp"

using namespace th::body;

namespace {

// A closed UV sphere: {vertices (N, 3), faces (F, 3)}.
std::pair<torch::Tensor, torch::Tensor> sphere(double radius, int rings, int segments) {
  std::vector<double> v{0, radius, 0};
  for (int r = 1; r < rings; ++r) {
    const double theta = M_PI * r / rings;
    for (int s = 0; s < segments; ++s) {
      const double phi = 2 * M_PI * s / segments;
      v.insert(v.end(), {radius * std::sin(theta) * std::cos(phi), radius * std::cos(theta),
                         radius * std::sin(theta) * std::sin(phi)});
    }
  }
  v.insert(v.end(), {0, -radius, 0});
  const int n = int(v.size() / 3), bottom = n - 1;
  std::vector<int64_t> f;
  auto ring = [&](int r, int s) { return 1 + (r - 1) * segments + (s % segments); };
  for (int s = 0; s < segments; ++s) f.insert(f.end(), {0, ring(1, s), ring(1, s + 1)});
  for (int r = 1; r < rings - 1; ++r)
    for (int s = 0; s < segments; ++s)
      f.insert(f.end(), {ring(r, s), ring(r + 1, s), ring(r + 1, s + 1), ring(r, s),
                         ring(r + 1, s + 1), ring(r, s + 1)});
  for (int s = 0; s < segments; ++s)
    f.insert(f.end(), {bottom, ring(rings - 1, s + 1), ring(rings - 1, s)});
  return {torch::tensor(v, torch::kFloat64).reshape({-1, 3}),
          torch::tensor(f, torch::kInt64).reshape({-1, 3})};
}

}  // namespace

TEST_CASE("the near side of a body is visible and the far side is not", "[visibility]") {
  auto [verts, faces] = sphere(0.3, 24, 48);
  const auto K = torch::tensor({300.0, 0.0, 64.0, 0.0, 300.0, 64.0, 0.0, 0.0, 1.0}, torch::kFloat64)
                     .reshape({3, 3});
  const auto R = torch::eye(3, torch::kFloat64);
  const auto T =
      torch::tensor({0.0, 0.0, 3.0}, torch::kFloat64).reshape({3, 1});  // camera at z = -3
  const auto vis = vertex_visibility(verts, faces, K, R, T, 128, 128);
  const auto z = verts.select(1, 2);
  // Facing the camera (z < 0 side, away from the silhouette) -> visible; far side -> hidden.
  const auto front = z<-0.1, back = z> 0.1;
  CHECK(vis.index({front}).all().item<bool>());
  CHECK_FALSE(vis.index({back}).any().item<bool>());
  // An occluder: a second sphere behind the first is hidden where the first covers it.
  auto [v2, f2] = sphere(0.1, 12, 24);
  const auto behind = v2 + torch::tensor({0.0, 0.0, 1.0}, torch::kFloat64);
  const auto all_v = torch::cat({verts, behind});
  const auto all_f = torch::cat({faces, f2 + verts.size(0)});
  const auto vis2 = vertex_visibility(all_v, all_f, K, R, T, 128, 128);
  CHECK_FALSE(vis2.slice(0, verts.size(0)).any().item<bool>());
}

TEST_CASE("vertices projecting outside the image are invisible", "[visibility]") {
  auto [verts, faces] = sphere(0.3, 12, 24);
  const auto K = torch::tensor({300.0, 0.0, 64.0, 0.0, 300.0, 64.0, 0.0, 0.0, 1.0}, torch::kFloat64)
                     .reshape({3, 3});
  const auto R = torch::eye(3, torch::kFloat64);
  const auto T = torch::tensor({5.0, 0.0, 3.0}, torch::kFloat64).reshape({3, 1});  // far off-image
  CHECK_FALSE(vertex_visibility(verts, faces, K, R, T, 128, 128).any().item<bool>());
}
