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

void validate_section(const DataConfig& c, const std::string& path) {
  require(c.ratio >= 0.01 && c.ratio <= 1, path, "ratio", c.ratio, "must be in [0.01, 1]");
  require(c.patch.count > 0 && c.patch.count <= 1024, path, "patch.count", c.patch.count,
          "must be in [1, 1024]");
  require(c.patch.size > 0 && c.patch.size <= 4096, path, "patch.size", c.patch.size,
          "must be in [1, 4096]");
  require(std::isfinite(c.box_padding) && c.box_padding >= 0, path, "box_padding", c.box_padding,
          "must be a finite number >= 0 (metres)");
  require(c.patch.body_prob >= 0 && c.patch.body_prob <= 1, path, "patch.body_prob",
          c.patch.body_prob, "must be a probability");
  require(c.workers >= 0 && c.workers <= 256, path, "workers", c.workers, "must be in [0, 256]");
  require(c.prefetch >= 1 && c.prefetch <= 1024, path, "prefetch", c.prefetch,
          "must be in [1, 1024]");
  require(c.person_id >= -1, path, "person_id", c.person_id,
          "must be a person's id (>= 0) or -1 (the only one)");
  require(c.num_reference_views >= 1 && c.num_reference_views <= 64, path, "num_reference_views",
          c.num_reference_views, "must be in [1, 64]");
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
  require(g.num_tokens > 0 && g.num_tokens <= 6890, path, "grouping.num_tokens", g.num_tokens,
          "must be in [1, 6890] (SMPL's vertex count)");
  require(c.transhe.dim >= 1, path, "transhe.dim", c.transhe.dim, "must be positive");
  require(c.transhe.depth >= 1 && c.transhe.depth <= 64, path, "transhe.depth", c.transhe.depth,
          "must be in [1, 64] (transhe.enabled: false turns the transformer off)");
  require(c.transhe.mlp_dim >= 1, path, "transhe.mlp_dim", c.transhe.mlp_dim, "must be positive");
  require(std::isfinite(c.transhe.pe_scale) && c.transhe.pe_scale > 0, path, "transhe.pe_scale",
          c.transhe.pe_scale, "must be a finite positive number");
  require(c.spc.channels >= 1, path, "spc.channels", c.spc.channels, "must be positive");
  require(c.dparf.nk >= 1 && c.dparf.nk <= g.num_tokens, path, "dparf.nk", c.dparf.nk,
          "must be between 1 and grouping.num_tokens");
  require(std::isfinite(c.dparf.softmax_temperature) && c.dparf.softmax_temperature > 0, path,
          "dparf.softmax_temperature", c.dparf.softmax_temperature, "must be positive");
  require(c.transhe.heads > 0 && c.transhe.dim % c.transhe.heads == 0, path, "transhe.heads",
          c.transhe.heads, "must divide transhe.dim");
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

void validate_section(const RenderConfig& c, const std::string& path) {
  require(c.samples >= 2 && c.samples <= 4096, path, "samples", c.samples, "must be in [2, 4096]");
  require(std::isfinite(c.cull_distance) && c.cull_distance > 0, path, "cull_distance",
          c.cull_distance, "must be a finite positive number");
  require(c.chunk_points >= 1024 && c.chunk_points <= (1 << 24), path, "chunk_points",
          c.chunk_points, "must be in [1024, 16777216]");
  require(c.termination_transmittance >= 0 && c.termination_transmittance < 1, path,
          "termination_transmittance", c.termination_transmittance, "must be in [0, 1) (0: off)");
  require(c.train_chunk_points >= 256 && c.train_chunk_points <= (1 << 24), path,
          "train_chunk_points", c.train_chunk_points, "must be in [256, 16777216]");
}

void validate_section(const TrainConfig& c, const std::string& path) {
  require(std::isfinite(c.lr) && c.lr > 0, path, "lr", c.lr, "must be a finite positive number");
  require(std::isfinite(c.min_lr) && c.min_lr >= 0 && c.min_lr <= c.lr, path, "min_lr", c.min_lr,
          "must be in [0, train.lr]");
  require(c.beta1 >= 0 && c.beta1 < 1, path, "beta1", c.beta1, "must be in [0, 1)");
  require(c.beta2 >= 0 && c.beta2 < 1, path, "beta2", c.beta2, "must be in [0, 1)");
  require(std::isfinite(c.eps) && c.eps > 0, path, "eps", c.eps,
          "must be a finite positive number");
  require(c.epochs > 0 && c.epochs <= 10000000, path, "epochs", c.epochs,
          "must be in [1, 10000000]");
  require(c.iters_per_epoch > 0 && c.iters_per_epoch <= 10000000, path, "iters_per_epoch",
          c.iters_per_epoch, "must be in [1, 10000000]");
  require(c.val_views >= 0 && c.val_views <= 1024, path, "val_views", c.val_views,
          "must be in [0, 1024]");
  require(c.warmup_epochs >= 0 && c.warmup_epochs < c.epochs, path, "warmup_epochs",
          c.warmup_epochs, "must be in [0, epochs)");
  require(std::isfinite(c.grad_clip) && c.grad_clip > 0, path, "grad_clip", c.grad_clip,
          "must be a finite positive number");
  require(std::isfinite(c.lpips_weight) && c.lpips_weight >= 0, path, "lpips_weight",
          c.lpips_weight, "must be a finite number >= 0");
  require(c.save_every_epochs >= 0, path, "save_every_epochs", c.save_every_epochs,
          "must be >= 0 (0: only at the end)");
  require(c.val_every_epochs >= 0, path, "val_every_epochs", c.val_every_epochs,
          "must be >= 0 (0: only at the end)");
  require(c.log_every_steps > 0, path, "log_every_steps", c.log_every_steps, "must be positive");
  require(std::isfinite(c.max_minutes) && c.max_minutes >= 0, path, "max_minutes", c.max_minutes,
          "must be a finite number >= 0 (0: no limit)");
  require(c.dist_timeout_s > 0 && c.dist_timeout_s <= 86400, path, "dist_timeout_s",
          c.dist_timeout_s, "must be in (0, 86400] seconds");
  require(c.dist_bucket_mb > 0 && c.dist_bucket_mb <= 4096, path, "dist_bucket_mb",
          c.dist_bucket_mb, "must be in (0, 4096]");
}

void validate_section(const EvalConfig& c, const std::string& path) {
  require(c.limit >= 0, path, "limit", c.limit, "must be >= 0 (0: every image)");
}

void validate_section(const Config& c, const std::string& path) {
  require(c.threads >= 0 && c.threads <= 4096, path, "threads", c.threads,
          "must be in [0, 4096] (0: one per core)");
  require(std::isfinite(c.max_memory_gb) && c.max_memory_gb >= 0, path, "max_memory_gb",
          c.max_memory_gb, "must be a finite number >= 0 (0: 3/4 of physical memory)");
}

}  // namespace th
