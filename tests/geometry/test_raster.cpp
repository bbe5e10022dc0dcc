// The z-buffer rasteriser (lib/render/raster) against hand computations: coverage by an
// independent point-in-triangle test, depth by ray-plane intersection, barycentrics that
// reproduce the 3D point seen through the pixel.

#include <torch/torch.h>

#include <catch2/catch.hpp>

#include "geometry/camera.hpp"
#include "geometry/mesh.hpp"
#include "render/raster.hpp"

using th::render::rasterize;

namespace {

torch::Tensor K_64() {
  return torch::tensor({80.0, 0.0, 31.5, 0.0, 80.0, 31.5, 0.0, 0.0, 1.0}, torch::kFloat64)
      .reshape({3, 3});
}

// Signed-area point-in-triangle test in pixel space (independent of the rasteriser's code).
bool inside(double px, double py, const double (&u)[3], const double (&v)[3]) {
  auto edge = [&](int a, int b) {
    return (u[b] - u[a]) * (py - v[a]) - (v[b] - v[a]) * (px - u[a]);
  };
  const double e0 = edge(0, 1), e1 = edge(1, 2), e2 = edge(2, 0);
  return (e0 >= 0 && e1 >= 0 && e2 >= 0) || (e0 <= 0 && e1 <= 0 && e2 <= 0);
}

}  // namespace

TEST_CASE("rasterize covers exactly the pixel centres inside a triangle", "[raster]") {
  // A slanted triangle in front of the camera.
  auto verts = torch::tensor({-0.3, -0.2, 2.0, 0.35, -0.1, 2.5, 0.0, 0.4, 1.8}, torch::kFloat64)
                   .reshape({3, 3});
  auto faces = torch::tensor({0, 1, 2}, torch::kInt64).reshape({1, 3});
  auto r = rasterize(verts, faces, K_64(), 64, 64);
  auto uv = th::geometry::project(verts, K_64());
  double u[3], v[3];
  for (int i = 0; i < 3; ++i) u[i] = uv[i][0].item<double>(), v[i] = uv[i][1].item<double>();
  int mismatches = 0, covered = 0;
  for (int y = 0; y < 64; ++y)
    for (int x = 0; x < 64; ++x) {
      const bool in = inside(x, y, u, v);
      const bool hit = r.face_id[y][x].item<int>() == 0;
      covered += hit;
      mismatches += in != hit;
    }
  CHECK(covered > 100);
  CHECK(mismatches == 0);
  CHECK(r.face_id.min().item<int>() == -1);
  CHECK(std::isinf(r.depth[0][0].item<float>()));
}

TEST_CASE("depth is the camera z of the surface and barycentrics are perspective-correct",
          "[raster]") {
  auto verts = torch::tensor({-0.5, -0.5, 1.5, 0.6, -0.4, 3.0, -0.1, 0.7, 2.2}, torch::kFloat64)
                   .reshape({3, 3});
  auto faces = torch::tensor({0, 1, 2}, torch::kInt64).reshape({1, 3});
  auto K = K_64();
  auto r = rasterize(verts, faces, K, 64, 64);
  // Plane through the triangle: n . x = d.
  auto n = torch::cross(verts[1] - verts[0], verts[2] - verts[0], 0);
  const double d = (n * verts[0]).sum().item<double>();
  auto Kinv = torch::inverse(K);
  int checked = 0;
  for (int y = 0; y < 64; y += 3)
    for (int x = 0; x < 64; x += 3) {
      if (r.face_id[y][x].item<int>() != 0) continue;
      auto ray = torch::matmul(Kinv, torch::tensor({double(x), double(y), 1.0}, torch::kFloat64));
      const double t = d / (n * ray).sum().item<double>();  // ray has z = 1: t is the depth
      CHECK(r.depth[y][x].item<float>() == Approx(t).epsilon(1e-5));
      auto b = r.bary[y][x].to(torch::kFloat64);
      CHECK(b.sum().item<double>() == Approx(1.0).epsilon(1e-6));
      auto point = torch::matmul(b.unsqueeze(0), verts).squeeze(0);
      CHECK(torch::allclose(point, ray * t, 0, 1e-5));
      ++checked;
    }
  CHECK(checked > 20);
}

TEST_CASE("the nearer of two overlapping triangles wins", "[raster]") {
  auto verts = torch::tensor({-1.0, -1.0, 3.0, 1.0, -1.0, 3.0, 0.0, 1.0, 3.0,   // far
                              -1.0, -1.0, 2.0, 1.0, -1.0, 2.0, 0.0, 1.0, 2.0},  // near
                             torch::kFloat64)
                   .reshape({6, 3});
  for (bool near_first : {true, false}) {
    auto faces = near_first ? torch::tensor({3, 4, 5, 0, 1, 2}, torch::kInt64).reshape({2, 3})
                            : torch::tensor({0, 1, 2, 3, 4, 5}, torch::kInt64).reshape({2, 3});
    auto r = rasterize(verts, faces, K_64(), 64, 64);
    const int near_id = near_first ? 0 : 1;
    CHECK(r.face_id[40][32].item<int>() == near_id);
    CHECK(r.depth[40][32].item<float>() == Approx(2.0f));
  }
}

TEST_CASE("faces listed in cull disappear only when seen from behind", "[raster]") {
  // Wound counter-clockwise seen from the camera at the origin: its outward side faces it.
  auto front = torch::tensor({-0.5, -0.5, 2.0, 0.0, 0.5, 2.0, 0.5, -0.5, 2.0}, torch::kFloat64)
                   .reshape({3, 3});
  auto n = torch::cross(front[1] - front[0], front[2] - front[0], 0);
  REQUIRE(n[2].item<double>() < 0);  // outward normal points at the camera
  auto faces = torch::tensor({0, 1, 2}, torch::kInt64).reshape({1, 3});
  auto flipped = torch::tensor({0, 2, 1}, torch::kInt64).reshape({1, 3});
  th::render::RasterOptions cull;
  cull.cull = torch::ones({1}, torch::kBool);
  CHECK(rasterize(front, faces, K_64(), 64, 64, cull).face_id[36][32].item<int>() == 0);
  CHECK(rasterize(front, flipped, K_64(), 64, 64, cull).face_id[36][32].item<int>() == -1);
  CHECK(rasterize(front, flipped, K_64(), 64, 64).face_id[36][32].item<int>() == 0);
}

TEST_CASE("interpolate blends vertex attributes with the barycentrics", "[raster]") {
  auto verts = torch::tensor({-0.5, -0.5, 2.0, 0.5, -0.5, 2.0, 0.0, 0.5, 2.0}, torch::kFloat64)
                   .reshape({3, 3});
  auto faces = torch::tensor({0, 1, 2}, torch::kInt64).reshape({1, 3});
  auto r = rasterize(verts, faces, K_64(), 64, 64);
  // Interpolating the camera-space positions gives back the point on the pixel's ray.
  auto pos = th::render::interpolate(r, faces, verts);
  REQUIRE(pos.sizes() == torch::IntArrayRef({64, 64, 3}));
  CHECK(pos[32][32][2].item<float>() == Approx(2.0f));
  CHECK(pos[32][32][0].item<float>() == Approx((32 - 31.5) / 80.0 * 2.0).margin(1e-5));
  CHECK(pos[0][0].abs().sum().item<float>() == 0.0f);
}

TEST_CASE("vertex normals of a closed mesh point outwards and a unit cube has volume 1",
          "[geometry]") {
  // Unit cube, faces wound counter-clockwise seen from outside.
  auto v = torch::tensor({0., 0., 0., 1., 0., 0., 1., 1., 0., 0., 1., 0.,
                          0., 0., 1., 1., 0., 1., 1., 1., 1., 0., 1., 1.},
                         torch::kFloat64)
               .reshape({8, 3});
  auto f = torch::tensor({0, 2, 1, 0, 3, 2, 4, 5, 6, 4, 6, 7, 0, 1, 5, 0, 5, 4,
                          2, 3, 7, 2, 7, 6, 1, 2, 6, 1, 6, 5, 0, 4, 7, 0, 7, 3},
                         torch::kInt64)
               .reshape({12, 3});
  CHECK(th::geometry::signed_volume(v, f) == Approx(1.0));
  auto n = th::geometry::vertex_normals(v, f);
  auto centre = torch::full({1, 3}, 0.5, torch::kFloat64);
  CHECK(((n * (v - centre)).sum(1) > 0).all().item<bool>());
  CHECK(torch::allclose(n.norm(2, 1), torch::ones({8}, torch::kFloat64)));
}
