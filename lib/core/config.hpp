#pragma once
// The option tree of TransHuman-C++ with the defaults of docs/METHOD.md. configs/default.yaml
// states the same values; a test checks that the two agree. Each module receives the section it
// needs.

#include <cstdint>
#include <string>
#include <vector>

#include "core/config_io.hpp"

namespace th {

// ---- choices, parsed once into enums (their YAML names listed once, config_io.hpp) ---------
enum class DatasetKind { zju_mocap, h36m, synthetic, capture };
enum class DataLayout { automatic, zju_mocap, easymocap };
enum class VisibilitySource { rasterize, files };
enum class MissingVisibility { error, all_visible };
enum class CalibrationCheck { error, warn };
enum class BorderBand { distorted, undistorted };
enum class BatchNormStats { batch, running };
enum class GroupingKind { canonical_kmeans, canonical_grid, observation_grid };
enum class MeanOver { all, visible };
enum class TokenPosition { canonical, observation };
enum class PeRounding { fused, separate };
enum class Coordinate { relative, absolute, none };
enum class Representation { transhuman, spc_trilinear };
enum class Recompute { automatic, always, never };
enum class MismatchPolicy { error, warn };

#define TH_CHOICE_NAMES(E, ...)                             \
  inline const config::ChoiceNames<E>& choice_names(E) {    \
    static const config::ChoiceNames<E> names{__VA_ARGS__}; \
    return names;                                           \
  }
TH_CHOICE_NAMES(DatasetKind, {"zju_mocap", DatasetKind::zju_mocap}, {"h36m", DatasetKind::h36m},
                {"synthetic", DatasetKind::synthetic}, {"capture", DatasetKind::capture})
TH_CHOICE_NAMES(DataLayout, {"auto", DataLayout::automatic}, {"zju_mocap", DataLayout::zju_mocap},
                {"easymocap", DataLayout::easymocap})
TH_CHOICE_NAMES(VisibilitySource, {"rasterize", VisibilitySource::rasterize},
                {"files", VisibilitySource::files})
TH_CHOICE_NAMES(MissingVisibility, {"error", MissingVisibility::error},
                {"all_visible", MissingVisibility::all_visible})
TH_CHOICE_NAMES(CalibrationCheck, {"error", CalibrationCheck::error},
                {"warn", CalibrationCheck::warn})
TH_CHOICE_NAMES(BorderBand, {"distorted", BorderBand::distorted},
                {"undistorted", BorderBand::undistorted})
TH_CHOICE_NAMES(BatchNormStats, {"batch", BatchNormStats::batch},
                {"running", BatchNormStats::running})
TH_CHOICE_NAMES(GroupingKind, {"canonical_kmeans", GroupingKind::canonical_kmeans},
                {"canonical_grid", GroupingKind::canonical_grid},
                {"observation_grid", GroupingKind::observation_grid})
TH_CHOICE_NAMES(MeanOver, {"all", MeanOver::all}, {"visible", MeanOver::visible})
TH_CHOICE_NAMES(TokenPosition, {"canonical", TokenPosition::canonical},
                {"observation", TokenPosition::observation})
TH_CHOICE_NAMES(PeRounding, {"fused", PeRounding::fused}, {"separate", PeRounding::separate})
TH_CHOICE_NAMES(Coordinate, {"relative", Coordinate::relative}, {"absolute", Coordinate::absolute},
                {"none", Coordinate::none})
TH_CHOICE_NAMES(Representation, {"transhuman", Representation::transhuman},
                {"spc_trilinear", Representation::spc_trilinear})
TH_CHOICE_NAMES(MismatchPolicy, {"error", MismatchPolicy::error}, {"warn", MismatchPolicy::warn})
TH_CHOICE_NAMES(Recompute, {"auto", Recompute::automatic}, {"always", Recompute::always},
                {"never", Recompute::never})
#undef TH_CHOICE_NAMES

// ---- data (METHOD 1, 2.1, 5) --------------------------------------------------------------
struct PatchConfig {
  int count = 6;           // patches per target image
  int size = 20;           // side in pixels
  double body_prob = 0.8;  // probability that a patch centre lies on the person
};

struct JitterConfig {
  bool enabled = true;  // training only; same parameters for target and references
  std::vector<double> brightness{0.2, 2.0};
  std::vector<double> contrast{0.3, 2.0};
  std::vector<double> saturation{0.2, 2.0};
  std::vector<double> hue{-0.5, 0.5};
};

struct DataConfig {
  DatasetKind dataset = DatasetKind::synthetic;  // zju_mocap | h36m | synthetic | capture
  std::string root = "data/synthetic";           // folder holding one folder per human
  DataLayout layout = DataLayout::automatic;     // auto | zju_mocap | easymocap (data/sequence.hpp)
  int person_id = -1;  // easymocap: the person's id in the SMPL files; -1: the only one
  // Empty: every person under data.root, every frame; references as below, the other cameras
  // targets.
  std::string split_file = "data_splits/synthetic.yaml";
  // Fixed reference cameras by name or index, replacing the setting's; empty: the split's, or
  // without a split the num_reference_views cameras most evenly spread around the body.
  std::vector<std::string> reference_views;
  int num_reference_views = 3;  // without a split file
  std::string train_setting = "training";
  std::string test_setting = "identity";  // pose | identity | one_shot | cross_dataset | fitting
  std::string smpl_model = "";            // SMPL .pkl/.npz; empty: <root>/smpl_model.npz
  double ratio = 0.5;                     // image resize factor
  VisibilitySource visibility = VisibilitySource::rasterize;  // rasterize | files
  std::string visibility_root = "";  // for visibility: files (NHP's zju_rasterization)
  MissingVisibility visibility_missing =
      MissingVisibility::error;  // files: error | all_visible (warns)
  double box_padding = 0.05;     // world AABB padding on z (metres)
  // Calibration that cannot be right (intrinsics, rotations, the body out of a reference view or
  // at an implausible distance; data/calibration.hpp): an error, or a warning.
  CalibrationCheck calibration_check = CalibrationCheck::error;  // error | warn
  // Target mask border band (METHOD 2.1 step 6): marked on the distorted mask before undistortion
  // [parity], or on the undistorted one.
  BorderBand border_band = BorderBand::distorted;  // distorted | undistorted
  PatchConfig patch;
  JitterConfig jitter;
  int workers = 2;   // background loader threads
  int prefetch = 4;  // samples queued ahead
};

// ---- model (METHOD 2.5, 3) -----------------------------------------------------------------
struct EncoderConfig {
  std::string pretrained = "";  // ResNet-18 weights file from scripts/export_pretrained.py
  BatchNormStats batchnorm = BatchNormStats::batch;  // batch [parity] | running
  bool fast_sampling = true;  // METHOD 3.1/9: sample low-res maps, no (V,384,H,W) tensor
};

// model.grouping.kmeans_file's value that imports a reference checkpoint with token groups computed
// here instead of the reference's own (METHOD 8): its renders then differ from the reference's.
inline constexpr const char* kKMeansCompute = "compute";

struct GroupingConfig {
  GroupingKind kind = GroupingKind::canonical_kmeans;
  int num_tokens = 300;             // Nt
  std::string kmeans_file = "";     // reference kmeans_dict_300.npy; "compute": see kKMeansCompute
  std::string cache_dir = "cache";  // k-means labels cached here, keyed by model and Nt
  int64_t seed = 0;
  MeanOver mean_over = MeanOver::all;  // all [parity] | visible
};

struct TransHEConfig {
  bool enabled = true;  // false: tokens go straight to DPaRF (w/o transformer)
  TokenPosition position = TokenPosition::canonical;  // observation: PE of posed token centres
  int dim = 192;
  int depth = 12;
  int heads = 3;
  int mlp_dim = 768;
  int pe_freqs = 32;
  double pe_scale = 1.5;  // Pc = mean(v_template[c]) / pe_scale
  // float32 sin(x * f + phase): "fused" rounds once, as the reference's torch.addcmul (FMA)
  // [parity, METHOD 3.2]; "separate" rounds the product and the sum (numpy's evaluation).
  PeRounding pe_rounding = PeRounding::fused;
};

struct DPaRFConfig {
  int nk = 7;  // nearest fields
  Coordinate coordinate = Coordinate::relative;
  double softmax_temperature = 0.5;  // w = softmax(-d / T)
  int pe_freqs = 10;
  PeRounding pe_rounding = PeRounding::fused;  // fused [parity] | separate, as transhe.pe_rounding
};

struct FDIConfig {
  bool appearance = true;  // a: image features of the reference views
  bool human = true;       // h: the human representation branch
  bool raw_rgb = true;     // upsample_color channels in p_v
};

struct SPCConfig {
  double voxel_size = 0.005 * 4;  // coarse grid for the SPC + trilinear baseline
  int channels = 64;
};

struct ModelConfig {
  Representation representation = Representation::transhuman;
  EncoderConfig encoder;
  GroupingConfig grouping;
  TransHEConfig transhe;
  DPaRFConfig dparf;
  FDIConfig fdi;
  SPCConfig spc;
  // METHOD 9 identities (per-level readouts of p_v, fc_0 on the tokens, folded linear layers);
  // false: the reference's direct computation (slower; for checking).
  bool exact_shortcuts = true;
  // METHOD 9 readout windows (with exact_shortcuts, inference on CPU): the readouts at full
  // resolution on a rectangle of each view around the body; false: per-level tables.
  bool readout_windows = true;
};

// ---- rendering (METHOD 4) ------------------------------------------------------------------
struct RenderConfig {
  int samples = 64;            // per ray (16: the paper's fast variant)
  bool progressive = true;     // inference: distance culling, colour only where sigma > 0
  double cull_distance = 0.1;  // metres from the nearest body vertex
  int64_t chunk_points =
      4096;  // per-point work in chunks of this many points (bench/results/model.md)
  // Progressive rendering marches each ray front to back and stops once its transmittance is
  // below this bound: the samples it skips change rgb and acc by at most the bound (METHOD 4 note
  // in render/progressive.hpp). 0: every kept sample is evaluated (the exact render).
  double termination_transmittance = 1e-4;
  // Training: chunk of the per-point network, recomputed in the backward pass (bounded memory).
  int64_t train_chunk_points = 4096;
  // Training: "always" evaluates the per-point network without a graph and recomputes each chunk
  // in the backward pass (memory of one chunk); "never" keeps every chunk's graph from the
  // forward pass (one forward less; memory grows with the points); "auto" keeps them up to
  // model::kKeepGraphPoints points per field call (the demo's batch) and recomputes beyond.
  // The same arithmetic in the same order either way: the same weights, bit for bit.
  Recompute train_recompute = Recompute::automatic;
};

// ---- training (METHOD 5) -------------------------------------------------------------------
struct TrainConfig {
  int epochs = 3000;
  int iters_per_epoch = 500;
  double lr = 7e-4;
  double min_lr = 1e-6;
  int warmup_epochs = 300;
  double beta1 = 0.9;
  double beta2 = 0.999;
  double eps = 1e-8;
  double grad_clip = 40.0;  // element-wise
  double lpips_weight = 0.1;
  std::string lpips_weights = "";  // file from scripts/export_lpips.py; empty: term off
  bool skip_far_points = false;    // cull points > cull_distance from the body in training too
  int save_every_epochs = 10;      // 0: only the final checkpoint (latest.pt is always written)
  int val_every_epochs = 10;       // 0: validate only after the last epoch
  int val_views = 2;
  int log_every_steps = 10;
  double max_minutes = 0;  // stop (with a checkpoint) after this wall time; 0: no limit
  // Data-parallel training (several ranks, lib/dist): c10d backend, how long a rank waits for
  // the others before it gives up with an error, and the size of the gradient all-reduce buckets.
  std::string dist_backend = "auto";  // auto (nccl on CUDA when built in, else gloo) | gloo | nccl
  double dist_timeout_s = 300;
  double dist_bucket_mb = 25;
  // With several ranks, the encoder's BatchNorm normalises over every rank's images together
  // (statistics summed over the ranks, forward and backward) [parity: the reference trains
  // with SyncBatchNorm]; false: each rank's own images.
  bool sync_batchnorm = true;
};

// ---- evaluation (METHOD 6) -----------------------------------------------------------------
struct EvalConfig {
  std::string setting = "identity";
  std::string lpips_weights = "";
  int limit = 0;  // 0: all images
  bool save_images = true;
  // Target views of one frame share its prepared stages (encoder, TransHE, DPaRF tokens, painted
  // vertices; they depend only on the frame's inputs, compared value by value). false: every
  // view prepares its frame again.
  bool reuse_frames = true;
  // A checkpoint trained with other model.* values (its stored config, or its run's config.yaml):
  // "error" names the keys and stops; "warn" names them and goes on (a deliberate ablation).
  MismatchPolicy model_mismatch = MismatchPolicy::error;
};

struct Config {
  int64_t seed = 42;
  std::string device = "auto";  // auto | cpu | cuda
  // Floating-point type of the network's matrix products (model/precision.hpp): fp32 (the
  // paper's numbers), bf16, or auto (bf16 where the processor has native bf16 dot products).
  std::string precision = "fp32";
  // fp32 products on CPU: auto (oneDNN when LibTorch has it) | onednn | blas.
  std::string fp32_products = "auto";
  int threads = 0;  // 0: one per core
  // Refuse work whose estimated peak memory (render, mesh) exceeds this; 0: 3/4 of physical memory.
  double max_memory_gb = 0;
  DataConfig data;
  ModelConfig model;
  RenderConfig render;
  TrainConfig train;
  EvalConfig eval;
};

// ---- field lists -------------------------------------------------------------------------
template <class V>
void visit_fields(V& v, PatchConfig& c) {
  v("count", c.count);
  v("size", c.size);
  v("body_prob", c.body_prob);
}
template <class V>
void visit_fields(V& v, JitterConfig& c) {
  v("enabled", c.enabled);
  v("brightness", c.brightness);
  v("contrast", c.contrast);
  v("saturation", c.saturation);
  v("hue", c.hue);
}
template <class V>
void visit_fields(V& v, DataConfig& c) {
  v.choice("dataset", c.dataset);
  v("root", c.root);
  v.choice("layout", c.layout);
  v("person_id", c.person_id);
  v("split_file", c.split_file);
  v("reference_views", c.reference_views);
  v("num_reference_views", c.num_reference_views);
  v("train_setting", c.train_setting);
  v("test_setting", c.test_setting);
  v("smpl_model", c.smpl_model);
  v("ratio", c.ratio);
  v.choice("visibility", c.visibility);
  v("visibility_root", c.visibility_root);
  v.choice("visibility_missing", c.visibility_missing);
  v("box_padding", c.box_padding);
  v.choice("calibration_check", c.calibration_check);
  v.choice("border_band", c.border_band);
  v("patch", c.patch);
  v("jitter", c.jitter);
  v("workers", c.workers);
  v("prefetch", c.prefetch);
}
template <class V>
void visit_fields(V& v, EncoderConfig& c) {
  v("pretrained", c.pretrained);
  v.choice("batchnorm", c.batchnorm);
  v("fast_sampling", c.fast_sampling);
}
template <class V>
void visit_fields(V& v, GroupingConfig& c) {
  v.choice("kind", c.kind);
  v("num_tokens", c.num_tokens);
  v("kmeans_file", c.kmeans_file);
  v("cache_dir", c.cache_dir);
  v("seed", c.seed);
  v.choice("mean_over", c.mean_over);
}
template <class V>
void visit_fields(V& v, TransHEConfig& c) {
  v("enabled", c.enabled);
  v.choice("position", c.position);
  v("dim", c.dim);
  v("depth", c.depth);
  v("heads", c.heads);
  v("mlp_dim", c.mlp_dim);
  v("pe_freqs", c.pe_freqs);
  v("pe_scale", c.pe_scale);
  v.choice("pe_rounding", c.pe_rounding);
}
template <class V>
void visit_fields(V& v, DPaRFConfig& c) {
  v("nk", c.nk);
  v.choice("coordinate", c.coordinate);
  v("softmax_temperature", c.softmax_temperature);
  v("pe_freqs", c.pe_freqs);
  v.choice("pe_rounding", c.pe_rounding);
}
template <class V>
void visit_fields(V& v, FDIConfig& c) {
  v("appearance", c.appearance);
  v("human", c.human);
  v("raw_rgb", c.raw_rgb);
}
template <class V>
void visit_fields(V& v, SPCConfig& c) {
  v("voxel_size", c.voxel_size);
  v("channels", c.channels);
}
template <class V>
void visit_fields(V& v, ModelConfig& c) {
  v.choice("representation", c.representation);
  v("encoder", c.encoder);
  v("grouping", c.grouping);
  v("transhe", c.transhe);
  v("dparf", c.dparf);
  v("fdi", c.fdi);
  v("spc", c.spc);
  v("exact_shortcuts", c.exact_shortcuts);
  v("readout_windows", c.readout_windows);
}
template <class V>
void visit_fields(V& v, RenderConfig& c) {
  v("samples", c.samples);
  v("progressive", c.progressive);
  v("cull_distance", c.cull_distance);
  v("chunk_points", c.chunk_points);
  v("termination_transmittance", c.termination_transmittance);
  v("train_chunk_points", c.train_chunk_points);
  v.choice("train_recompute", c.train_recompute);
}
template <class V>
void visit_fields(V& v, TrainConfig& c) {
  v("epochs", c.epochs);
  v("iters_per_epoch", c.iters_per_epoch);
  v("lr", c.lr);
  v("min_lr", c.min_lr);
  v("warmup_epochs", c.warmup_epochs);
  v("beta1", c.beta1);
  v("beta2", c.beta2);
  v("eps", c.eps);
  v("grad_clip", c.grad_clip);
  v("lpips_weight", c.lpips_weight);
  v("lpips_weights", c.lpips_weights);
  v("skip_far_points", c.skip_far_points);
  v("save_every_epochs", c.save_every_epochs);
  v("val_every_epochs", c.val_every_epochs);
  v("val_views", c.val_views);
  v("log_every_steps", c.log_every_steps);
  v("max_minutes", c.max_minutes);
  v.choice("dist_backend", c.dist_backend, {"auto", "gloo", "nccl"});
  v("dist_timeout_s", c.dist_timeout_s);
  v("dist_bucket_mb", c.dist_bucket_mb);
  v("sync_batchnorm", c.sync_batchnorm);
}
template <class V>
void visit_fields(V& v, EvalConfig& c) {
  v("setting", c.setting);
  v("lpips_weights", c.lpips_weights);
  v("limit", c.limit);
  v("save_images", c.save_images);
  v("reuse_frames", c.reuse_frames);
  v.choice("model_mismatch", c.model_mismatch);
}
template <class V>
void visit_fields(V& v, Config& c) {
  v("seed", c.seed);
  v.choice("device", c.device, {"auto", "cpu", "cuda"});
  v.choice("precision", c.precision, {"fp32", "bf16", "auto"});
  v.choice("fp32_products", c.fp32_products, {"auto", "onednn", "blas"});
  v("threads", c.threads);
  v("max_memory_gb", c.max_memory_gb);
  v("data", c.data);
  v("model", c.model);
  v("render", c.render);
  v("train", c.train);
  v("eval", c.eval);
}

// Value checks across fields (ranges, incompatible ablation switches); throw th::Error.
void validate_section(const DataConfig& c, const std::string& path);
void validate_section(const ModelConfig& c, const std::string& path);
void validate_section(const RenderConfig& c, const std::string& path);
void validate_section(const TrainConfig& c, const std::string& path);
void validate_section(const EvalConfig& c, const std::string& path);
void validate_section(const Config& c, const std::string& path);

}  // namespace th
