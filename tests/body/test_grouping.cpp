#include <catch2/catch.hpp>
#include <fstream>

#include "body/grouping.hpp"
#include "io/npy.hpp"
#include "io/pickle.hpp"
#include "support/test_env.hpp"

using namespace th::body;

namespace {

// A body-like point cloud: points on a few elongated ellipsoids (torso, limbs, head).
torch::Tensor body_like_points(int n, int64_t seed) {
  torch::manual_seed(seed);
  const std::vector<std::array<double, 6>> parts = {
      // centre x, y, z, radii x, y, z
      {0.0, 0.3, 0.0, 0.17, 0.3, 0.1},      {0.0, 0.8, 0.0, 0.1, 0.12, 0.1},
      {-0.45, 0.5, 0.0, 0.3, 0.05, 0.05},   {0.45, 0.5, 0.0, 0.3, 0.05, 0.05},
      {-0.1, -0.45, 0.0, 0.07, 0.45, 0.07}, {0.1, -0.45, 0.0, 0.07, 0.45, 0.07}};
  std::vector<torch::Tensor> pts;
  for (const auto& p : parts) {
    auto dir = torch::randn({n / int(parts.size()), 3}, torch::kFloat64);
    dir = dir / dir.norm(2, 1, true);
    pts.push_back(dir * torch::tensor({p[3], p[4], p[5]}, torch::kFloat64) +
                  torch::tensor({p[0], p[1], p[2]}, torch::kFloat64));
  }
  return torch::cat(pts);
}

}  // namespace

TEST_CASE("k-means puts every vertex in one cluster and leaves none empty", "[grouping]") {
  const auto pts = body_like_points(3000, 1);
  const auto labels = kmeans(pts, 100, 7);
  REQUIRE(labels.sizes() == torch::IntArrayRef({pts.size(0)}));
  CHECK(labels.min().item<int64_t>() == 0);
  CHECK(labels.max().item<int64_t>() == 99);
  CHECK((cluster_sizes(labels) > 0).all().item<bool>());
  // Each point belongs to its nearest centre (Lloyd converged).
  const auto centres = torch::zeros({100, 3}, torch::kFloat64).index_add_(0, labels, pts) /
                       cluster_sizes(labels).to(torch::kFloat64).unsqueeze(1);
  const auto nearest = (pts.unsqueeze(1) - centres.unsqueeze(0)).pow(2).sum(-1).argmin(1);
  CHECK((nearest == labels).to(torch::kFloat64).mean().item<double>() > 0.999);
}

TEST_CASE("k-means gives the same labels for the same seed and others for another", "[grouping]") {
  const auto pts = body_like_points(2000, 2);
  CHECK(torch::equal(kmeans(pts, 50, 3), kmeans(pts, 50, 3)));
  CHECK_FALSE(torch::equal(kmeans(pts, 50, 3), kmeans(pts, 50, 4)));
}

TEST_CASE("k-means labels are cached on disk and reused", "[grouping]") {
  const auto dir = th::test::scratch_dir("kmeans_cache");
  const auto pts = body_like_points(1200, 3);
  const auto first = kmeans_cached(pts, 40, 0, dir);
  size_t files = 0;
  for (const auto& e : std::filesystem::directory_iterator(dir))
    files += e.path().extension() == ".npy";
  CHECK(files == 1);
  CHECK(torch::equal(kmeans_cached(pts, 40, 0, dir), first));
  // Another body (or k) gets its own entry.
  kmeans_cached(pts * 1.1, 40, 0, dir);
  files = 0;
  for (const auto& e : std::filesystem::directory_iterator(dir))
    files += e.path().extension() == ".npy";
  CHECK(files == 2);
}

TEST_CASE("k-means clusters are more even in size than grid cells (paper appendix)", "[grouping]") {
  const auto pts = body_like_points(6000, 4);
  const auto km = cluster_sizes(kmeans(pts, 300, 0)).to(torch::kFloat64);
  const auto grid = cluster_sizes(grid_labels(pts, 300)).to(torch::kFloat64);
  const double km_cv = (km.std() / km.mean()).item<double>();
  const double grid_cv = (grid.std() / grid.mean()).item<double>();
  std::printf(
      "cluster sizes, coefficient of variation: k-means %.3f (%lld clusters), "
      "canonical grid %.3f (%lld cells)\n",
      km_cv, (long long)km.numel(), grid_cv, (long long)grid.numel());
  CHECK(km_cv < grid_cv);
  CHECK(std::abs(grid.numel() - 300) <= 30);
}

TEST_CASE("the grouping kind of the config selects the implementation", "[grouping]") {
  const auto pts = body_like_points(1200, 5);
  th::GroupingConfig c;
  c.num_tokens = 30;
  c.cache_dir = th::test::scratch_dir("grouping_factory").string();
  auto km = make_grouping(c);
  CHECK(km->is_static());
  CHECK(km->labels(pts, pts).max().item<int64_t>() == 29);
  c.kind = th::GroupingKind::observation_grid;
  auto obs = make_grouping(c);
  CHECK_FALSE(obs->is_static());
  // Observation-space labels follow the posed points: a stretched pose groups differently.
  const auto posed = pts * torch::tensor({2.0, 1.0, 1.0}, torch::kFloat64);
  CHECK_FALSE(torch::equal(obs->labels(pts, pts), obs->labels(pts, posed)));
}

TEST_CASE("the reference's k-means file (numpy-scalar dict keys) loads with numpy's labels",
          "[grouping][parity]") {
  // METHOD 2.5: kmeans_dict_300.npy as the reference ships it; np.save of a dict whose
  // dict_voxel2pc_ind is keyed by numpy.int32 scalars (refused as unhashable before).
  const auto dir = th::test::scratch_dir("kmeans_reference_file");
  const int64_t nv = 300, clusters = 24;
  REQUIRE(th::test::run_python(
              "tests/python/kmeans_reference.py",
              dir.string() + " " + std::to_string(nv) + " " + std::to_string(clusters)) == 0);
  const auto labels = load_reference_kmeans(dir / "kmeans_dict.npy", nv);
  std::ifstream expected((dir / "labels.txt").string());
  std::vector<int64_t> numpy_labels;
  for (int64_t l; expected >> l;) numpy_labels.push_back(l);
  REQUIRE(int64_t(numpy_labels.size()) == nv);
  CHECK(torch::equal(labels, torch::tensor(numpy_labels)));  // every label used: no compaction

  // The grouping with kmeans_file set takes those labels.
  th::GroupingConfig g;
  g.num_tokens = clusters;
  g.kmeans_file = (dir / "kmeans_dict.npy").string();
  CHECK(torch::equal(make_grouping(g)->labels(torch::rand({nv, 3}, torch::kFloat64), {}), labels));

  // The dict of groups reads with plain integer keys equal to numpy's.
  const auto value = th::io::read_npy_value(dir / "kmeans_dict.npy");
  const auto& groups = value["dict_voxel2pc_ind"].as_dict();
  std::ifstream g_expected((dir / "groups.txt").string());
  size_t i = 0;
  for (int64_t key, count, first; g_expected >> key >> count >> first; ++i) {
    REQUIRE(i < groups.size());
    INFO("group " << i);
    CHECK(groups[i].first.kind() == th::io::Value::Kind::Int);
    CHECK(groups[i].first.as_int() == key);
    CHECK(groups[i].second.as_tensor().numel() == count);
    CHECK(groups[i].second.as_tensor()[0].item<int64_t>() == first);
  }
  CHECK(i == groups.size());
}

TEST_CASE("numpy scalars of every integer, bool and float dtype are plain dict keys",
          "[grouping][parity]") {
  const auto dir = th::test::scratch_dir("numpy_scalar_keys");
  REQUIRE(th::test::run_python("tests/python/kmeans_reference.py", dir.string() + " 30 4") == 0);
  const auto value = th::io::read_npy_value(dir / "scalar_keys.npy");
  const auto& d = value.as_dict();
  std::ifstream expected((dir / "scalar_keys.txt").string());
  size_t i = 0;
  for (std::string kind, text; expected >> kind >> text; ++i) {
    int64_t index = -1;
    expected >> index;
    REQUIRE(i < d.size());
    INFO("key " << i << ": " << kind << " " << text);
    const auto& key = d[i].first;
    if (kind == "b") {
      CHECK(key.kind() == th::io::Value::Kind::Bool);
      CHECK(key.as_int() == std::stoll(text));
    } else if (kind == "f") {
      CHECK(key.kind() == th::io::Value::Kind::Float);
      CHECK(key.as_float() == std::stod(text));
    } else {
      CHECK(key.kind() == th::io::Value::Kind::Int);
      CHECK(key.as_int() == std::stoll(text));
    }
    CHECK(d[i].second.as_int() == index);
  }
  CHECK(i == d.size());
  CHECK(i == 14);
}
