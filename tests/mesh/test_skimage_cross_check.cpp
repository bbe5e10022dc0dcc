// Cross-check against scikit-image's marching cubes (an independent implementation) on a field
// with saddles: the same crossing points (one vertex per crossed grid edge, linear
// interpolation, world coordinates) and nearly the same area. The two differ only in ambiguous
// cubes: Lewiner's method adds interior vertices and tunnels where this one fans polygons.

#include <torch/torch.h>

#include <catch2/catch.hpp>

#include "io/npy.hpp"
#include "mesh/marching_cubes.hpp"
#include "mesh_checks.hpp"
#include "support/test_env.hpp"

TEST_CASE("crossing points and area agree with scikit-image", "[mesh][marching_cubes][python]") {
  const auto dir = th::test::scratch_dir("mesh_skimage");
  REQUIRE(th::test::run_python("tests/mesh/skimage_reference.py", dir.string() + " 0.02") == 0);
  auto field = th::io::read_npy(dir / "field.npy");
  auto sk_verts = th::io::read_npy(dir / "sk_verts.npy");
  const double sk_area = th::io::read_npy(dir / "sk_area.npy")[0].item<double>();

  const th::mesh::GridSpec grid{{0.1, -0.2, 0.3}, {0.03, 0.025, 0.02}};
  const auto mesh = th::mesh::marching_cubes(field, grid, {0.5, 0});
  const auto top = th::test::topology(mesh);
  CHECK(top.closed());
  CHECK(top.oriented());

  auto ours = mesh.verts.to(torch::kFloat64);
  auto d = torch::cdist(sk_verts, ours);
  auto sk_matched = std::get<0>(d.min(1)) < 1e-5;
  auto ours_matched = std::get<0>(d.min(0)) < 1e-5;
  INFO("ours " << ours.size(0) << " (" << ours_matched.sum().item<int64_t>()
               << " matched), scikit-image " << sk_verts.size(0) << " ("
               << sk_matched.sum().item<int64_t>() << " matched)");
  const int64_t n_ours = ours.size(0), n_sk = sk_verts.size(0);
  // Unmatched: our polygon centroids, scikit-image's (Lewiner's) interior vertices.
  CHECK(n_ours - ours_matched.sum().item<int64_t>() <= n_ours / 100);
  CHECK(n_sk - sk_matched.sum().item<int64_t>() <= n_sk / 100);
  CHECK(ours_matched.sum().item<int64_t>() == sk_matched.sum().item<int64_t>());

  const double area = th::mesh::surface_area(mesh);
  INFO("area " << area << " scikit-image " << sk_area);
  CHECK(std::abs(area / sk_area - 1.0) < 0.002);
}
