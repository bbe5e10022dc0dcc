#include "body/grouping.hpp"

#include <spdlog/spdlog.h>

#include <limits>
#include <random>

#include "core/config_io.hpp"
#include "core/error.hpp"
#include "io/npy.hpp"

namespace th::body {
namespace fs = std::filesystem;

namespace {

torch::Tensor sq_distances(const torch::Tensor& x, const torch::Tensor& c) {
  // (N, 3), (K, 3) -> (N, K) squared distances, float64.
  return (x.unsqueeze(1) - c.unsqueeze(0)).pow(2).sum(-1);
}

uint64_t fnv1a(const void* data, size_t size, uint64_t h = 1469598103934665603ull) {
  const auto* p = static_cast<const unsigned char*>(data);
  for (size_t i = 0; i < size; ++i) h = (h ^ p[i]) * 1099511628211ull;
  return h;
}

class CanonicalKMeans : public Grouping {
 public:
  explicit CanonicalKMeans(GroupingConfig c) : c_(std::move(c)) {}
  torch::Tensor labels(const torch::Tensor& canonical, const torch::Tensor&) override {
    if (!labels_.defined()) {
      labels_ = uses_reference_kmeans(c_)
                    ? load_reference_kmeans(c_.kmeans_file, canonical.size(0))
                    : kmeans_cached(canonical, c_.num_tokens, c_.seed, c_.cache_dir);
    }
    return labels_;
  }
  bool is_static() const override { return true; }

 private:
  GroupingConfig c_;
  torch::Tensor labels_;
};

class CanonicalGrid : public Grouping {
 public:
  explicit CanonicalGrid(int cells) : cells_(cells) {}
  torch::Tensor labels(const torch::Tensor& canonical, const torch::Tensor&) override {
    if (!labels_.defined()) labels_ = grid_labels(canonical, cells_);
    return labels_;
  }
  bool is_static() const override { return true; }

 private:
  int cells_;
  torch::Tensor labels_;
};

class ObservationGrid : public Grouping {
 public:
  explicit ObservationGrid(int cells) : cells_(cells) {}
  torch::Tensor labels(const torch::Tensor&, const torch::Tensor& posed_smpl) override {
    return grid_labels(posed_smpl, cells_);
  }
  bool is_static() const override { return false; }

 private:
  int cells_;
};

}  // namespace

torch::Tensor kmeans(const torch::Tensor& points, int k, int64_t seed, int max_iterations) {
  TORCH_CHECK(points.dim() == 2 && points.size(1) == 3, "points must be (N, 3)");
  const auto x = points.to(torch::kFloat64).contiguous();
  const int64_t n = x.size(0);
  if (k <= 0 || k > n) fail("k-means: cannot make ", k, " clusters of ", n, " points");
  std::mt19937_64 rng{static_cast<uint64_t>(seed)};

  // k-means++ seeding.
  std::vector<int64_t> chosen{int64_t(std::uniform_int_distribution<int64_t>(0, n - 1)(rng))};
  auto d2 = sq_distances(x, x[chosen[0]].unsqueeze(0)).squeeze(1);
  for (int c = 1; c < k; ++c) {
    const auto cdf = d2.cumsum(0);
    const double total = cdf[-1].item<double>();
    const double r = std::uniform_real_distribution<double>(0.0, total)(rng);
    int64_t idx = torch::searchsorted(cdf, torch::tensor({r}, torch::kFloat64)).item<int64_t>();
    idx = std::min(idx, n - 1);
    chosen.push_back(idx);
    d2 = torch::minimum(d2, sq_distances(x, x[idx].unsqueeze(0)).squeeze(1));
  }
  auto centres = x.index({torch::tensor(chosen)});

  torch::Tensor labels;
  for (int it = 0; it < max_iterations; ++it) {
    const auto dist = sq_distances(x, centres);
    auto new_labels = dist.argmin(1);
    // Re-seed empty clusters with the points farthest from their current centre.
    auto counts = torch::bincount(new_labels, {}, k);
    auto empty = (counts == 0).nonzero().reshape({-1});
    if (empty.numel() > 0) {
      auto own = dist.gather(1, new_labels.unsqueeze(1)).squeeze(1).clone();
      for (int64_t e = 0; e < empty.numel(); ++e) {
        const int64_t far = own.argmax().item<int64_t>();
        new_labels[far] = empty[e];
        own[far] = -1.0;
      }
    }
    const bool converged = labels.defined() && torch::equal(new_labels, labels);
    labels = new_labels;
    if (converged) break;
    centres = torch::zeros({k, 3}, torch::kFloat64).index_add_(0, labels, x) /
              torch::bincount(labels, {}, k).to(torch::kFloat64).unsqueeze(1);
  }
  return labels;
}

torch::Tensor kmeans_cached(const torch::Tensor& points, int k, int64_t seed,
                            const fs::path& cache_dir) {
  const auto x = points.to(torch::kFloat64).contiguous();
  const uint64_t h = fnv1a(x.data_ptr(), size_t(x.numel()) * sizeof(double));
  char name[96];
  std::snprintf(name, sizeof name, "kmeans_%016llx_k%d_s%lld.npy", (unsigned long long)h, k,
                (long long)seed);
  const fs::path file = cache_dir / name;
  if (fs::exists(file)) {
    auto labels = io::read_npy(file).to(torch::kInt64);
    if (labels.numel() == x.size(0) && labels.min().item<int64_t>() >= 0 &&
        labels.max().item<int64_t>() < k)
      return labels;
    spdlog::warn("k-means cache '{}' does not fit this body; recomputing", file.string());
  }
  spdlog::info("k-means: {} clusters of {} canonical vertices (cached in {})", k, x.size(0),
               file.string());
  auto labels = kmeans(x, k, seed);
  // The cache only saves time (a run stores its labels in every checkpoint): a folder that cannot
  // be written (a read-only checkout) costs the k-means again next time, nothing else.
  std::error_code ec;
  fs::create_directories(cache_dir, ec);
  try {
    if (ec) fail("cannot create the folder: ", ec.message());
    io::write_npy(file, labels);
  } catch (const Error& e) {
    spdlog::warn("k-means labels not cached in '{}' ({}): model.grouping.cache_dir",
                 cache_dir.string(), e.what());
  }
  return labels;
}

torch::Tensor load_reference_kmeans(const fs::path& file, int64_t num_vertices) {
  const io::Value v = io::read_npy_value(file);
  const io::Value* labels = v.find("pc2voxel_ind");
  if (!labels) fail("'", file.string(), "' has no 'pc2voxel_ind' (expected kmeans_dict_300.npy)");
  auto t = labels->as_tensor().to(torch::kInt64).reshape({-1});
  if (t.numel() == 0) fail("'", file.string(), "' has no labels in 'pc2voxel_ind'");
  if (t.min().item<int64_t>() < 0)
    fail("'", file.string(), "' has negative labels in 'pc2voxel_ind'");
  if (num_vertices >= 0 && t.numel() != num_vertices)
    fail("'", file.string(), "' labels ", t.numel(), " vertices, the body has ", num_vertices);
  // Compact to [0, clusters) in case some label is unused.
  return std::get<1>(torch::_unique(t, /*sorted=*/true, /*return_inverse=*/true));
}

bool uses_reference_kmeans(const GroupingConfig& c) {
  return !c.kmeans_file.empty() && c.kmeans_file != kKMeansCompute;
}

std::string describe(const GroupingConfig& c) {
  const std::string kind = config::name_of(c.kind);
  switch (c.kind) {
    case GroupingKind::canonical_kmeans:
      if (uses_reference_kmeans(c)) return kind + " from the reference file " + c.kmeans_file;
      return kind + " num_tokens=" + std::to_string(c.num_tokens) +
             " seed=" + std::to_string(c.seed);
    case GroupingKind::canonical_grid:
      return kind + " num_tokens=" + std::to_string(c.num_tokens);
    case GroupingKind::observation_grid:
      return kind + " num_tokens=" + std::to_string(c.num_tokens) +
             " (per frame, from the posed body)";
  }
  return kind;
}

void check_labels(const torch::Tensor& labels, const std::string& source) {
  if (labels.scalar_type() != torch::kInt64 || labels.dim() != 1 || labels.numel() == 0)
    fail(source, ": token labels must be a non-empty 1-D int64 tensor, not ", labels.scalar_type(),
         " of shape ", labels.sizes());
  const int64_t lo = labels.min().item<int64_t>(), hi = labels.max().item<int64_t>();
  if (lo < 0 || hi >= labels.numel())
    fail(source, ": token labels run from ", lo, " to ", hi, " for ", labels.numel(), " vertices");
  const int64_t empty = (torch::bincount(labels) == 0).sum().item<int64_t>();
  if (empty > 0) fail(source, ": ", empty, " of the ", hi + 1, " tokens hold no vertex");
}

torch::Tensor grid_labels(const torch::Tensor& points, int target_cells) {
  TORCH_CHECK(points.dim() == 2 && points.size(1) == 3, "points must be (N, 3)");
  const auto x = points.to(torch::kFloat64);
  const auto lo = std::get<0>(x.min(0));
  const double extent = (std::get<0>(x.max(0)) - lo).max().item<double>();
  auto label_with = [&](double cell, int64_t& count) {
    const auto idx = ((x - lo) / cell).floor().to(torch::kInt64);
    const int64_t side = int64_t(extent / cell) + 2;
    const auto key = (idx.select(1, 0) * side + idx.select(1, 1)) * side + idx.select(1, 2);
    auto [uniq, inverse] = torch::_unique(key, /*sorted=*/true, /*return_inverse=*/true);
    count = uniq.numel();
    return inverse;
  };
  // Occupied cells decrease with the cell size: bisect (in log space) for target_cells.
  double small = extent / 2000.0, large = extent * 2.0;
  torch::Tensor best;
  int64_t best_gap = std::numeric_limits<int64_t>::max();
  for (int it = 0; it < 40; ++it) {
    const double cell = std::sqrt(small * large);
    int64_t count = 0;
    auto labels = label_with(cell, count);
    if (std::abs(count - target_cells) < best_gap)
      best_gap = std::abs(count - target_cells), best = labels;
    if (count == target_cells) break;
    (count > target_cells ? small : large) = cell;
  }
  return best;
}

torch::Tensor cluster_sizes(const torch::Tensor& labels) {
  return torch::bincount(labels.reshape({-1}));
}

std::unique_ptr<Grouping> make_grouping(const GroupingConfig& c) {
  switch (c.kind) {
    case GroupingKind::canonical_kmeans:
      return std::make_unique<CanonicalKMeans>(c);
    case GroupingKind::canonical_grid:
      return std::make_unique<CanonicalGrid>(c.num_tokens);
    case GroupingKind::observation_grid:
      return std::make_unique<ObservationGrid>(c.num_tokens);
  }
  fail("unknown grouping kind ", int(c.kind));
}

}  // namespace th::body
