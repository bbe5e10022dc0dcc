// Marching cubes (METHOD 7) on analytic fields: closed, consistently oriented, welded meshes whose
// area, volume and genus match the analytic shapes; slab-by-slab equals whole-grid extraction.

#include <torch/torch.h>

#include <catch2/catch.hpp>
#include <cmath>
#include <functional>

#include "geometry/mesh.hpp"
#include "mesh/marching_cubes.hpp"
#include "mesh_checks.hpp"

using th::mesh::GridSpec;
using th::mesh::MarchingCubes;
using th::mesh::MarchingCubesOptions;
using th::mesh::TriMesh;

namespace {

// Samples f at the grid's points: (D, H, W) float32, [k][j][i] at origin + (i, j, k) * voxel.
torch::Tensor sample(
    const GridSpec& g, int64_t d, int64_t h, int64_t w,
    const std::function<torch::Tensor(torch::Tensor, torch::Tensor, torch::Tensor)>& f) {
  auto axis = [](double o, double s, int64_t n) {
    return o + s * torch::arange(n, torch::kFloat64);
  };
  auto zyx = torch::meshgrid({axis(g.origin[2], g.voxel[2], d), axis(g.origin[1], g.voxel[1], h),
                              axis(g.origin[0], g.voxel[0], w)},
                             "ij");
  return f(zyx[2], zyx[1], zyx[0]).to(torch::kFloat32);
}

// A cube [lo, hi]^3 sampled n times per axis.
GridSpec cube_grid(double lo, double hi, int64_t n) {
  const double s = (hi - lo) / double(n - 1);
  return {{lo, lo, lo}, {s, s, s}};
}

// Signed-distance-like fields, positive inside (density convention: inside = high).
const double kCx = 0.0131, kCy = -0.0217, kCz = 0.0073;  // off-grid centre: no symmetric ties

torch::Tensor sphere(torch::Tensor x, torch::Tensor y, torch::Tensor z) {
  return 1.0 - ((x - kCx).square() + (y - kCy).square() + (z - kCz).square()).sqrt();
}

torch::Tensor torus(torch::Tensor x, torch::Tensor y, torch::Tensor z) {
  const double R = 0.6, r = 0.25;
  auto ring = ((x - kCx).square() + (y - kCy).square()).sqrt() - R;
  return r - (ring.square() + (z - kCz).square()).sqrt();
}

}  // namespace

TEST_CASE("sphere: closed, oriented outwards, welded, area and volume within 1%",
          "[mesh][marching_cubes]") {
  const int64_t n = 128;
  const GridSpec g = cube_grid(-1.2, 1.2, n);
  const TriMesh m = th::mesh::marching_cubes(sample(g, n, n, n, sphere), g, {0.0, 1});

  const auto top = th::test::topology(m);
  CHECK(top.closed());
  CHECK(top.oriented());
  CHECK(top.components == 1);
  CHECK(top.euler() == 2);  // genus 0
  CHECK(top.verts == m.num_verts());
  CHECK(th::test::duplicate_vertices(m) == 0);

  const double area = th::mesh::surface_area(m);
  const double volume = th::geometry::signed_volume(m.verts, m.faces);
  INFO("area " << area << " volume " << volume);
  CHECK(std::abs(area / (4.0 * M_PI) - 1.0) < 0.01);
  CHECK(std::abs(volume / (4.0 / 3.0 * M_PI) - 1.0) < 0.01);  // positive: outward faces

  // Vertices lie on the sphere (world coordinates: origin and voxel size applied), and every
  // face normal points away from the centre (towards lower values).
  auto v = m.verts.to(torch::kFloat64);
  auto c = torch::tensor({kCx, kCy, kCz}, torch::kFloat64);
  CHECK((v - c).norm(2, 1).sub(1.0).abs().max().item<double>() < 1e-3);
  auto a = v.index_select(0, m.faces.select(1, 0)), b = v.index_select(0, m.faces.select(1, 1)),
       cc = v.index_select(0, m.faces.select(1, 2));
  auto normal = torch::cross(b - a, cc - a, 1);
  auto outward = (normal * ((a + b + cc) / 3.0 - c)).sum(1);
  CHECK(outward.min().item<double>() >= 0.0);
}

TEST_CASE("torus has genus 1 and a sphere genus 0 (Euler characteristic)",
          "[mesh][marching_cubes]") {
  const GridSpec g = cube_grid(-1.0, 1.0, 72);
  const TriMesh t = th::mesh::marching_cubes(sample(g, 72, 72, 72, torus), g, {0.0, 1});
  const auto top = th::test::topology(t);
  CHECK(top.closed());
  CHECK(top.oriented());
  CHECK(top.components == 1);
  CHECK(top.euler() == 0);  // V - E + F = 2 - 2g, g = 1
  const double R = 0.6, r = 0.25;
  CHECK(std::abs(th::geometry::signed_volume(t.verts, t.faces) / (2 * M_PI * M_PI * R * r * r) -
                 1.0) < 0.02);
  CHECK(std::abs(th::mesh::surface_area(t) / (4 * M_PI * M_PI * R * r) - 1.0) < 0.02);

  const GridSpec gs = cube_grid(-1.2, 1.2, 32);
  const TriMesh s = th::mesh::marching_cubes(sample(gs, 32, 32, 32, sphere), gs, {0.0, 1});
  const auto st = th::test::topology(s);
  CHECK(st.closed());
  CHECK(st.euler() == 2);
}

TEST_CASE("anisotropic voxels and a non-zero threshold map vertices to world coordinates",
          "[mesh][marching_cubes]") {
  // Density-like field 40 (1 - |p - c|^2) at threshold 20: the sphere of radius sqrt(1/2).
  const GridSpec g{{-1.0, -0.9, -0.8}, {0.02, 0.025, 0.03}};
  auto field = sample(g, 60, 76, 101, [](auto x, auto y, auto z) {
    return 40.0 * (1.0 - ((x - kCx).square() + (y - kCy).square() + (z - kCz).square()));
  });
  const TriMesh m = th::mesh::marching_cubes(field, g, {20.0, 0});
  auto r =
      (m.verts.to(torch::kFloat64) - torch::tensor({kCx, kCy, kCz}, torch::kFloat64)).norm(2, 1);
  CHECK(r.sub(std::sqrt(0.5)).abs().max().item<double>() < 2e-3);
  CHECK(th::test::topology(m).closed());
}

TEST_CASE("noise field: ambiguous cases everywhere still give a closed oriented mesh",
          "[mesh][marching_cubes]") {
  torch::manual_seed(7);
  auto field = torch::rand({23, 19, 27});
  const TriMesh m = th::mesh::marching_cubes(field, {{0, 0, 0}, {1, 1, 1}}, {0.5, 1});
  const auto top = th::test::topology(m);
  INFO("faces " << top.faces << " components " << top.components << " boundary "
                << top.boundary_edges << " non-manifold " << top.nonmanifold_edges
                << " misoriented " << top.misoriented_edges);
  CHECK(top.faces > 10000);
  CHECK(top.closed());
  CHECK(top.oriented());
  CHECK(top.euler() % 2 == 0);
  CHECK(top.verts == m.num_verts());
}

TEST_CASE("slab-by-slab extraction equals whole-grid extraction", "[mesh][marching_cubes]") {
  torch::manual_seed(3);
  // Smooth blobs plus noise: ambiguous faces and cubes on slab boundaries.
  const GridSpec g{{-0.3, 0.1, 0.2}, {0.05, 0.04, 0.03}};
  auto field =
      torch::rand({37, 22, 29}) * 0.6 + sample(g, 37, 22, 29, [&](auto x, auto y, auto z) {
        return (-(x - 0.4).square() / 0.2 - (y - 0.5).square() / 0.1 - (z - 0.7).square() / 0.15)
            .exp();
      });
  const MarchingCubesOptions options{0.7, 3};
  const TriMesh whole = th::mesh::marching_cubes(field, g, options);

  MarchingCubes mc(22, 29, g, options);
  int64_t z = 0;
  for (int64_t d : {1, 4, 1, 2, 9, 7, 13}) {
    mc.push(field.slice(0, z, z + d));
    z += d;
  }
  REQUIRE(z == 37);
  CHECK(mc.slices_pushed() == 37);
  const TriMesh slabs = mc.finish();
  CHECK(whole.num_faces() > 1000);
  CHECK(torch::equal(whole.verts, slabs.verts));
  CHECK(torch::equal(whole.faces, slabs.faces));

  // One slice at a time, as (H, W) tensors, in float64.
  MarchingCubes single(22, 29, g, options);
  for (int64_t k = 0; k < 37; ++k) single.push(field[k].to(torch::kFloat64));
  const TriMesh one = single.finish();
  CHECK(torch::equal(whole.verts, one.verts));
  CHECK(torch::equal(whole.faces, one.faces));
}

TEST_CASE("padding closes surfaces cut by the grid boundary and keeps world coordinates",
          "[mesh][marching_cubes]") {
  // A sphere of radius 1 in a grid that only reaches 0.8: cut open on all six sides.
  const GridSpec g = cube_grid(-0.8, 0.8, 33);
  auto field = sample(g, 33, 33, 33, sphere);
  const TriMesh open = th::mesh::marching_cubes(field, g, {0.0, 0});
  CHECK(th::test::topology(open).boundary_edges > 0);

  const TriMesh closed = th::mesh::marching_cubes(field, g, {0.0, 10});  // METHOD 7: 10 cells
  const auto top = th::test::topology(closed);
  CHECK(top.closed());
  CHECK(top.oriented());
  // Vertices stay in world coordinates: the inner ones are on the sphere, the ones closing
  // the boundary lie within half a voxel outside the sampled box.
  auto v = closed.verts.to(torch::kFloat64);
  CHECK(v.abs().max().item<double>() <= 0.8 + g.voxel[0] + 1e-6);
  CHECK(v.abs().max().item<double>() > 0.8);

  // A sphere well inside the grid: the same mesh with or without padding.
  const GridSpec g2 = cube_grid(-1.3, 1.3, 30);
  auto f2 = sample(g2, 30, 30, 30, sphere);
  const TriMesh a = th::mesh::marching_cubes(f2, g2, {0.0, 0});
  const TriMesh b = th::mesh::marching_cubes(f2, g2, {0.0, 10});
  REQUIRE(a.num_verts() == b.num_verts());
  CHECK(torch::equal(a.faces, b.faces));
  CHECK(torch::allclose(a.verts, b.verts, 0, 1e-6));
}

TEST_CASE("empty and full grids give empty meshes, bad slabs are rejected",
          "[mesh][marching_cubes]") {
  const GridSpec g = cube_grid(0, 1, 5);
  CHECK(th::mesh::marching_cubes(torch::zeros({5, 5, 5}), g, {0.5, 2}).num_faces() == 0);
  CHECK(th::mesh::marching_cubes(torch::ones({5, 5, 5}), g, {0.5, 0}).num_faces() == 0);
  // Full grid with padding: a closed box around it.
  const TriMesh box = th::mesh::marching_cubes(torch::ones({5, 5, 5}), g, {0.5, 1});
  CHECK(th::test::topology(box).closed());
  CHECK(th::geometry::signed_volume(box.verts, box.faces) > 0);

  MarchingCubes mc(4, 6, g);
  CHECK_THROWS(mc.push(torch::zeros({2, 4, 5})));
  auto nan = torch::zeros({1, 4, 6});
  nan[0][1][1] = NAN;
  CHECK_THROWS(mc.push(nan));
}

TEST_CASE("grid over bounds and slab points: the network's slab feeds marching cubes",
          "[mesh][marching_cubes]") {
  // numpy: len(np.arange(lo, hi + 0.05, 0.05)) = 16, 4 (0.15000000000000002 is past 0.15), 35.
  auto bounds = torch::tensor({{-0.31, 0.0, 0.0}, {0.42, 0.1, 1.7}}, torch::kFloat64);
  const auto grid = th::mesh::grid_over_bounds(bounds, 0.05);
  CHECK(grid.width == 16);
  CHECK(grid.height == 4);
  CHECK(grid.depth == 35);

  // A sphere evaluated "by the network" slab by slab on the points equals the whole grid.
  const auto g2 = th::mesh::grid_over_bounds(
      torch::tensor({{-1.1, -1.2, -1.15}, {1.1, 1.2, 1.15}}, torch::kFloat64), 0.1);
  auto density = [](const torch::Tensor& p) {  // (N, 3) -> (N)
    return 30.0 * (1.0 - p.to(torch::kFloat64).square().sum(1));
  };
  th::mesh::MarchingCubes mc(g2.height, g2.width, g2.spec, {20.0, 10});
  for (int64_t z = 0; z < g2.depth; z += 4) {
    const int64_t d = std::min<int64_t>(4, g2.depth - z);
    auto pts = th::mesh::slab_points(g2, z, d);
    CHECK(pts.size(0) == d * g2.height * g2.width);
    mc.push(density(pts).reshape({d, g2.height, g2.width}));
  }
  const auto slabs = mc.finish();
  auto all = th::mesh::slab_points(g2, 0, g2.depth);
  const auto whole = th::mesh::marching_cubes(density(all).reshape({g2.depth, g2.height, g2.width}),
                                              g2.spec, {20.0, 10});
  CHECK(torch::equal(slabs.faces, whole.faces));
  CHECK(torch::equal(slabs.verts, whole.verts));
  // Vertices on the sphere 30 (1 - r^2) = 20, r = sqrt(1/3), in world coordinates.
  CHECK(slabs.verts.to(torch::kFloat64)
            .norm(2, 1)
            .sub(std::sqrt(1.0 / 3.0))
            .abs()
            .max()
            .item<double>() < 0.01);
  CHECK(th::test::topology(slabs).closed());
}
