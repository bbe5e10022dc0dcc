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
enum class ViewRenderer { exact, baked };
enum class PrecisionChoice { fp32, bf16, automatic };
enum class Fp32Products { automatic, onednn, blas };

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
TH_CHOICE_NAMES(ViewRenderer, {"exact", ViewRenderer::exact}, {"baked", ViewRenderer::baked})
TH_CHOICE_NAMES(PrecisionChoice, {"fp32", PrecisionChoice::fp32}, {"bf16", PrecisionChoice::bf16},
                {"auto", PrecisionChoice::automatic})
TH_CHOICE_NAMES(Fp32Products, {"auto", Fp32Products::automatic}, {"onednn", Fp32Products::onednn},
                {"blas", Fp32Products::blas})
#undef TH_CHOICE_NAMES

// ---- the sections: each field's type and default; its key, accepted values and description
// are in the section's visit_fields below (config_io.hpp), written once --------------------
struct PatchConfig {
  int count = 6;
  int size = 20;
  double body_prob = 0.8;
};

struct JitterConfig {
  bool enabled = true;
  std::vector<double> brightness{0.2, 2.0};
  std::vector<double> contrast{0.3, 2.0};
  std::vector<double> saturation{0.2, 2.0};
  std::vector<double> hue{-0.5, 0.5};
};

struct DataConfig {
  DatasetKind dataset = DatasetKind::synthetic;
  std::string root = "data/synthetic";
  DataLayout layout = DataLayout::automatic;
  int person_id = -1;
  std::string split_file = "data_splits/synthetic.yaml";
  std::vector<std::string> reference_views;
  int num_reference_views = 3;
  std::string train_setting = "training";
  std::string test_setting = "identity";
  std::string smpl_model = "";
  double ratio = 0.5;
  VisibilitySource visibility = VisibilitySource::rasterize;
  std::string visibility_root = "";
  MissingVisibility visibility_missing = MissingVisibility::error;
  double box_padding = 0.05;
  CalibrationCheck calibration_check = CalibrationCheck::error;
  BorderBand border_band = BorderBand::distorted;
  PatchConfig patch;
  JitterConfig jitter;
  int workers = 2;
  int prefetch = 4;
};

struct EncoderConfig {
  std::string pretrained = "";
  BatchNormStats batchnorm = BatchNormStats::batch;
};

// model.grouping.kmeans_file's value that imports a reference checkpoint with token groups computed
// here instead of the reference's own (METHOD 8): its renders then differ from the reference's.
inline constexpr const char* kKMeansCompute = "compute";

struct GroupingConfig {
  GroupingKind kind = GroupingKind::canonical_kmeans;
  int num_tokens = 300;
  std::string kmeans_file = "";
  std::string cache_dir = "cache";
  int64_t seed = 0;
  MeanOver mean_over = MeanOver::all;
};

struct TransHEConfig {
  bool enabled = true;
  TokenPosition position = TokenPosition::canonical;
  int dim = 192;
  int depth = 12;
  int heads = 3;
  int mlp_dim = 768;
  int pe_freqs = 32;
  double pe_scale = 1.5;
  PeRounding pe_rounding = PeRounding::fused;
};

struct DPaRFConfig {
  int nk = 7;
  Coordinate coordinate = Coordinate::relative;
  double softmax_temperature = 0.5;
  int pe_freqs = 10;
  PeRounding pe_rounding = PeRounding::fused;
};

struct FDIConfig {
  bool appearance = true;
  bool human = true;
  bool raw_rgb = true;
};

struct SPCConfig {
  double voxel_size = 0.005 * 4;
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
};

struct RenderConfig {
  int samples = 64;
  bool progressive = true;
  double cull_distance = 0.1;
  int64_t chunk_points = 4096;
  double termination_transmittance = 1e-4;
  int64_t train_chunk_points = 4096;
  Recompute train_recompute = Recompute::automatic;
};

struct TrainConfig {
  int epochs = 3000;
  int iters_per_epoch = 500;
  double lr = 7e-4;
  double min_lr = 1e-6;
  int warmup_epochs = 300;
  double beta1 = 0.9;
  double beta2 = 0.999;
  double eps = 1e-8;
  double grad_clip = 40.0;
  double lpips_weight = 0.1;
  std::string lpips_weights = "";
  bool skip_far_points = false;
  int save_every_epochs = 10;
  int val_every_epochs = 10;
  int val_views = 2;
  ViewRenderer val_renderer = ViewRenderer::exact;
  int log_every_steps = 10;
  double max_minutes = 0;
  std::string dist_backend = "auto";
  double dist_timeout_s = 300;
  double dist_bucket_mb = 25;
  bool sync_batchnorm = true;
};

struct EvalConfig {
  std::string setting = "identity";
  std::string lpips_weights = "";
  int limit = 0;
  bool save_images = true;
  bool reuse_frames = true;
  MismatchPolicy model_mismatch = MismatchPolicy::error;
  ViewRenderer renderer = ViewRenderer::exact;
  double bake_voxel = 0.02;
};

struct Config {
  int64_t seed = 42;
  std::string device = "auto";
  PrecisionChoice precision = PrecisionChoice::fp32;
  Fp32Products fp32_products = Fp32Products::automatic;
  int threads = 0;
  double max_memory_gb = 0;
  DataConfig data;
  ModelConfig model;
  RenderConfig render;
  TrainConfig train;
  EvalConfig eval;
};

// ---- the keys ------------------------------------------------------------------------------
// ---- data (METHOD 1, 2.1, 5)
template <class V>
void visit_fields(V& v, PatchConfig& c) {
  v("count", c.count, config::in(1, 1024), "patches per target image");
  v("size", c.size, config::in(1, 4096), "a patch's side in pixels");
  v("body_prob", c.body_prob, config::in(0, 1),
    "probability that a patch's centre lies on the person");
}
template <class V>
void visit_fields(V& v, JitterConfig& c) {
  v("enabled", c.enabled, "colour jitter (training only; the same for target and references)");
  v("brightness", c.brightness, "factor range [low, high]");
  v("contrast", c.contrast, "factor range [low, high]");
  v("saturation", c.saturation, "factor range [low, high]");
  v("hue", c.hue, "shift range [low, high] in turns");
}
template <class V>
void visit_fields(V& v, DataConfig& c) {
  v.choice("dataset", c.dataset, "which data: capture is your own (docs/YOUR_CAPTURE.md)");
  v("root", c.root, "the folder holding one folder per person");
  v.choice("layout", c.layout,
           "a person's folder: ZJU-MoCap's (annots.npy) or EasyMocap's (intri.yml, extri.yml); "
           "auto tells them apart");
  v("person_id", c.person_id, config::at_least(-1),
    "easymocap: the person's id in the SMPL files; -1: the only one");
  v("split_file", c.split_file,
    "people, frames and cameras per setting; empty: every person and frame under root");
  v("reference_views", c.reference_views,
    "fixed reference cameras by name or index, replacing the split's; empty: the split's, or "
    "without a split the num_reference_views cameras most evenly spread around the body");
  v("num_reference_views", c.num_reference_views, config::in(1, 64),
    "reference cameras without a split file");
  v("train_setting", c.train_setting, "the split's setting trained on");
  v("test_setting", c.test_setting,
    "the split's setting evaluated: pose | identity | one_shot | cross_dataset | fitting");
  v("smpl_model", c.smpl_model, "SMPL .pkl/.npz; empty: <root>/smpl_model.npz");
  v("ratio", c.ratio, config::in(0.01, 1), "image resize factor (1024 px -> 512 px: 0.5)");
  v.choice("visibility", c.visibility,
           "vertex visibility per reference view: rasterized here, or read from NHP's files");
  v("visibility_root", c.visibility_root, "visibility: files: the folder of the files");
  v.choice("visibility_missing", c.visibility_missing,
           "visibility: files: a missing file is an error, or all vertices visible (warns)");
  v("box_padding", c.box_padding, config::at_least(0),
    "the world box's padding on z, in metres (METHOD 2.2)");
  v.choice("calibration_check", c.calibration_check,
           "calibration that cannot be right (intrinsics, rotations, the body out of a reference "
           "view or at an implausible distance): an error, or a warning");
  v.choice("border_band", c.border_band,
           "the target mask's border band (METHOD 2.1): marked before undistortion [parity], or "
           "after");
  v("patch", c.patch, "training rays (METHOD 5)");
  v("jitter", c.jitter, "colour jitter (METHOD 2.1)");
  v("workers", c.workers, config::in(0, 256), "background loader threads");
  v("prefetch", c.prefetch, config::in(1, 1024), "samples queued ahead");
}
// ---- model (METHOD 2.5, 3)
// What the retired execution keys of model.* (how the network was evaluated, never what it
// computes) say when a config still sets them.
inline constexpr const char* kRetiredExecutionKey =
    "the network always runs its fast forms (METHOD 9), chosen by device, precision and autograd";
template <class V>
void visit_fields(V& v, EncoderConfig& c) {
  v("pretrained", c.pretrained, "ResNet-18 weights (scripts/export_pretrained.py); empty: random");
  v.choice("batchnorm", c.batchnorm, "BatchNorm statistics: the batch's [parity] or running");
  v.retired("fast_sampling", kRetiredExecutionKey);
}
template <class V>
void visit_fields(V& v, GroupingConfig& c) {
  v.choice("kind", c.kind, "how SMPL's vertices are grouped into tokens (METHOD 3.2)");
  v("num_tokens", c.num_tokens, config::in(1, 6890),
    "Nt, the token count (SMPL has 6890 vertices)");
  v("kmeans_file", c.kmeans_file,
    "the reference's kmeans_dict_300.npy (needed to import its .pth), or compute; empty: the "
    "labels stored with the model");
  v("cache_dir", c.cache_dir, "k-means labels cached here, keyed by body model and Nt");
  v("seed", c.seed, "k-means seed");
  v.choice("mean_over", c.mean_over,
           "a token's feature: mean over all its vertices [parity] or the visible ones");
}
template <class V>
void visit_fields(V& v, TransHEConfig& c) {
  v("enabled", c.enabled, "the transformer; false: tokens go straight to DPaRF");
  v.choice("position", c.position,
           "the tokens' positional encoding: canonical centres, or posed (observation)");
  v("dim", c.dim, config::at_least(1), "token width");
  v("depth", c.depth, config::in(1, 64), "transformer blocks (enabled: false turns it off)");
  v("heads", c.heads, config::at_least(1), "attention heads (must divide dim)");
  v("mlp_dim", c.mlp_dim, config::at_least(1), "the blocks' MLP width");
  v("pe_freqs", c.pe_freqs, config::at_least(1), "positional-encoding frequencies (6 x = dim)");
  v("pe_scale", c.pe_scale, config::above(0), "Pc = mean(v_template[c]) / pe_scale");
  v.choice("pe_rounding", c.pe_rounding,
           "float32 sin(x f + phase): fused rounds once, as torch.addcmul [parity, METHOD 3.2]; "
           "separate rounds the product and the sum (numpy)");
}
template <class V>
void visit_fields(V& v, DPaRFConfig& c) {
  v("nk", c.nk, "nearest fields per point (1..grouping.num_tokens)");
  v.choice("coordinate", c.coordinate, "a point's coordinate in each field (METHOD 3.3)");
  v("softmax_temperature", c.softmax_temperature, config::above(0), "w = softmax(-d / T)");
  v("pe_freqs", c.pe_freqs, config::at_least(0), "positional-encoding frequencies of coordinates");
  v.choice("pe_rounding", c.pe_rounding, "fused [parity] | separate, as transhe.pe_rounding");
}
template <class V>
void visit_fields(V& v, FDIConfig& c) {
  v("appearance", c.appearance, "a: the reference views' image features");
  v("human", c.human, "h: the human representation branch");
  v("raw_rgb", c.raw_rgb, "the reference pixels' colours in p_v");
}
template <class V>
void visit_fields(V& v, SPCConfig& c) {
  v("voxel_size", c.voxel_size, "the grid's voxel in metres (representation: spc_trilinear)");
  v("channels", c.channels, config::at_least(1), "the grid's feature channels");
}
template <class V>
void visit_fields(V& v, ModelConfig& c) {
  v.choice("representation", c.representation,
           "transhuman, or spc_trilinear (the NHP-style baseline)");
  v("encoder", c.encoder, "image encoder (METHOD 2.5)");
  v("grouping", c.grouping, "token groups (METHOD 3.2)");
  v("transhe", c.transhe, "TransHE (METHOD 3.2)");
  v("dparf", c.dparf, "DPaRF (METHOD 3.3)");
  v("fdi", c.fdi, "FDI (METHOD 3.4)");
  v("spc", c.spc, "the SPC + trilinear baseline");
  v.retired("exact_shortcuts", kRetiredExecutionKey);
  v.retired("readout_windows", kRetiredExecutionKey);
}
// ---- rendering (METHOD 4)
template <class V>
void visit_fields(V& v, RenderConfig& c) {
  v("samples", c.samples, config::in(2, 4096), "samples per ray (16: the paper's fast variant)");
  v("progressive", c.progressive,
    "inference: distance culling, and colour only where the density is positive");
  v("cull_distance", c.cull_distance, config::above(0),
    "metres from the nearest body vertex beyond which a sample is empty");
  v("chunk_points", c.chunk_points, config::in(1024, 1 << 24),
    "per-point work in chunks of this many points (bench/results/model.md)");
  v("termination_transmittance", c.termination_transmittance, config::in_below(0, 1),
    "stop a ray once its transmittance is below this (changes rgb and acc by at most it); 0: "
    "every kept sample");
  v("train_chunk_points", c.train_chunk_points, config::in(256, 1 << 24),
    "training: the per-point network's chunk, recomputed in the backward pass");
  v.choice("train_recompute", c.train_recompute,
           "training: always recompute each chunk in the backward pass (memory of one chunk), "
           "never (keep every chunk's graph), or auto (keep up to model::kKeepGraphPoints points "
           "per field call); the same weights bit for bit");
}
// ---- training (METHOD 5)
template <class V>
void visit_fields(V& v, TrainConfig& c) {
  v("epochs", c.epochs, config::in(1, 10000000), "epochs");
  v("iters_per_epoch", c.iters_per_epoch, config::in(1, 10000000), "steps per epoch");
  v("lr", c.lr, config::above(0), "peak learning rate");
  v("min_lr", c.min_lr, config::at_least(0), "the cosine schedule's floor (at most lr)");
  v("warmup_epochs", c.warmup_epochs, config::at_least(0), "linear warm-up (fewer than epochs)");
  v("beta1", c.beta1, config::in_below(0, 1), "Adam's beta1");
  v("beta2", c.beta2, config::in_below(0, 1), "Adam's beta2");
  v("eps", c.eps, config::above(0), "Adam's epsilon");
  v("grad_clip", c.grad_clip, config::above(0), "element-wise gradient clip");
  v("lpips_weight", c.lpips_weight, config::at_least(0), "the perceptual term's weight");
  v("lpips_weights", c.lpips_weights,
    "LPIPS weights (scripts/export_lpips.py); empty: the perceptual term is off");
  v("skip_far_points", c.skip_far_points,
    "cull samples farther than render.cull_distance from the body in training too");
  v("save_every_epochs", c.save_every_epochs, config::at_least(0),
    "checkpoint interval; 0: only at the end (latest.pt is always written)");
  v("val_every_epochs", c.val_every_epochs, config::at_least(0),
    "validation interval; 0: only after the last epoch");
  v("val_views", c.val_views, config::in(0, 1024), "views rendered per validation");
  v.choice("val_renderer", c.val_renderer,
           "validation views: exact (the network per sample) or baked (each frame baked at "
           "eval.bake_voxel, its views marched through the grid; METHOD 7.1)");
  v("log_every_steps", c.log_every_steps, config::at_least(1), "metrics line interval");
  v("max_minutes", c.max_minutes, config::at_least(0),
    "stop with a checkpoint after this wall time; 0: no limit");
  v.choice("dist_backend", c.dist_backend, {"auto", "gloo", "nccl"},
           "several ranks: the c10d backend (auto: nccl on CUDA when built in, else gloo)");
  v("dist_timeout_s", c.dist_timeout_s, config::Range{0, 86400, true},
    "seconds a rank waits for the others before it stops with an error");
  v("dist_bucket_mb", c.dist_bucket_mb, config::Range{0, 4096, true},
    "gradient all-reduce bucket size in MiB");
  v("sync_batchnorm", c.sync_batchnorm,
    "several ranks: the encoder's BatchNorm over every rank's images [parity]; false: each "
    "rank's own");
}
// ---- evaluation (METHOD 6)
template <class V>
void visit_fields(V& v, EvalConfig& c) {
  v("setting", c.setting, "the split's setting scored");
  v("lpips_weights", c.lpips_weights, "LPIPS weights; empty: LPIPS is not scored");
  v("limit", c.limit, config::at_least(0), "images scored; 0: all");
  v("save_images", c.save_images, "write each rendered view beside its scores");
  v("reuse_frames", c.reuse_frames,
    "target views of one frame share its prepared stages (encoder, TransHE, DPaRF tokens); "
    "false: each view prepares its frame again");
  v.choice("model_mismatch", c.model_mismatch,
           "a checkpoint trained with other model.* values: error names the keys and stops, "
           "warn names them and goes on");
  v.choice("renderer", c.renderer,
           "exact (the network per sample: the paper's protocol) or baked (each frame baked once, "
           "its views marched through the grid: an approximate score; METHOD 7.1)");
  v("bake_voxel", c.bake_voxel, config::in(0.001, 0.2),
    "the baked renderer's lattice spacing, metres (eval.renderer and train.val_renderer baked)");
}
template <class V>
void visit_fields(V& v, Config& c) {
  v("seed", c.seed, "random seed");
  v.choice("device", c.device, {"auto", "cpu", "cuda"}, "where the network runs");
  v.choice("precision", c.precision,
           "the network's matrix products: fp32 (the paper's numbers), bf16, or auto (bf16 "
           "where the processor has native bf16 dot products; model/precision.hpp)");
  v.choice("fp32_products", c.fp32_products,
           "fp32 products on CPU: auto (oneDNN when LibTorch has it), onednn or blas");
  v("threads", c.threads, config::in(0, 4096), "CPU threads for LibTorch; 0: one per core");
  v("max_memory_gb", c.max_memory_gb, config::at_least(0),
    "refuse work (render, mesh) estimated to need more; 0: 3/4 of physical memory");
  v("data", c.data, "data (METHOD 1, 2.1)");
  v("model", c.model, "the network (METHOD 2.5, 3)");
  v("render", c.render, "rendering (METHOD 4)");
  v("train", c.train, "training (METHOD 5)");
  v("eval", c.eval, "evaluation (METHOD 6)");
}

// Checks across fields (incompatible switches, one value bounded by another); throw th::Error.
void validate_section(const DataConfig& c, const std::string& path);
void validate_section(const ModelConfig& c, const std::string& path);
void validate_section(const TrainConfig& c, const std::string& path);

}  // namespace th
