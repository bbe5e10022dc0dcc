#include "core/config.hpp"

#include <cmath>

namespace th {
namespace {

std::string key(const std::string& path, const char* name) {
  return config::detail::join_path(path, name);
}

template <class T>
void require(bool ok, const std::string& path, const char* name, const T& value, const char* why) {
  if (!ok) fail("config key '", key(path, name), "' = ", value, ": ", why);
}

void require_range(const std::vector<double>& r, const std::string& path, const char* name) {
  if (r.size() != 2 || r[0] > r[1])
    fail("config key '", key(path, name), "' must be a range [low, high] with low <= high");
}

}  // namespace

// Checks across fields only: a single field's type and range are declared with its key
// (config.hpp) and checked as it is read.

void validate_section(const DataConfig& c, const std::string& path) {
  for (const auto& v : c.reference_views)
    require(!v.empty(), path, "reference_views", "''", "holds an empty camera name");
  require(c.visibility != VisibilitySource::files || !c.visibility_root.empty(), path,
          "visibility_root", "''", "must name a folder when data.visibility is 'files'");
  require_range(c.jitter.brightness, path, "jitter.brightness");
  require_range(c.jitter.contrast, path, "jitter.contrast");
  require_range(c.jitter.saturation, path, "jitter.saturation");
  require_range(c.jitter.hue, path, "jitter.hue");
}

void validate_section(const ModelConfig& c, const std::string& path) {
  const auto& g = c.grouping;
  require(c.dparf.nk >= 1 && c.dparf.nk <= g.num_tokens, path, "dparf.nk", c.dparf.nk,
          "must be between 1 and grouping.num_tokens");
  require(c.transhe.dim % c.transhe.heads == 0, path, "transhe.heads", c.transhe.heads,
          "must divide transhe.dim");
  require(c.transhe.pe_freqs * 6 == c.transhe.dim, path, "transhe.pe_freqs", c.transhe.pe_freqs,
          "6 x pe_freqs (sin and cos of x, y, z per frequency) must equal transhe.dim");
  require(c.fdi.appearance || c.fdi.human, path, "fdi", "{appearance: false, human: false}",
          "at least one of the two branches must stay on");
  require(!g.kmeans_file.empty() ? g.kind == GroupingKind::canonical_kmeans : true, path,
          "grouping.kmeans_file", g.kmeans_file,
          "a k-means label file only applies to grouping.kind canonical_kmeans");
  require(
      !(g.kind == GroupingKind::observation_grid && c.transhe.position == TokenPosition::canonical),
      path, "transhe.position", config::name_of(c.transhe.position),
      "observation-space grouping has no canonical token position; use 'observation'");
  if (c.representation == Representation::spc_trilinear) {
    require(c.fdi.human, path, "fdi.human", "false",
            "the SPC + trilinear baseline is a human representation; it needs fdi.human");
    require(c.spc.voxel_size > 0, path, "spc.voxel_size", c.spc.voxel_size, "must be positive");
  }
}

void validate_section(const TrainConfig& c, const std::string& path) {
  require(c.min_lr <= c.lr, path, "min_lr", c.min_lr, "must be in [0, train.lr]");
  require(c.warmup_epochs < c.epochs, path, "warmup_epochs", c.warmup_epochs,
          "must be in [0, epochs)");
}

}  // namespace th
