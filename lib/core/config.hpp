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

// ---- the sections: one line per key with its type, default, accepted values and description
// (config_io.hpp) ------------------------------------------------------------------------------

// ---- data (METHOD 1, 2.1, 5)
#define TH_PATCH_KEYS(X)                                                 \
  X(key, int, count, 6, config::in(1, 1024), "patches per target image") \
  X(key, int, size, 20, config::in(1, 4096), "a patch's side in pixels") \
  X(key, double, body_prob, 0.8, config::in(0, 1),                       \
    "probability that a patch's centre lies on the person")
TH_CONFIG_SECTION(PatchConfig, TH_PATCH_KEYS)

#define TH_JITTER_KEYS(X)                                                      \
  X(key, bool, enabled, true, {},                                              \
    "colour jitter (training only; the same for target and references)")       \
  X(key, std::vector<double>, brightness, (std::vector<double>{0.2, 2.0}), {}, \
    "factor range [low, high]")                                                \
  X(key, std::vector<double>, contrast, (std::vector<double>{0.3, 2.0}), {},   \
    "factor range [low, high]")                                                \
  X(key, std::vector<double>, saturation, (std::vector<double>{0.2, 2.0}), {}, \
    "factor range [low, high]")                                                \
  X(key, std::vector<double>, hue, (std::vector<double>{-0.5, 0.5}), {},       \
    "shift range [low, high] in turns")
TH_CONFIG_SECTION(JitterConfig, TH_JITTER_KEYS)

#define TH_DATA_KEYS(X)                                                                            \
  X(choice, DatasetKind, dataset, DatasetKind::synthetic, ,                                        \
    "which data: capture is your own (docs/YOUR_CAPTURE.md)")                                      \
  X(key, std::string, root, "data/synthetic", {}, "the folder holding one folder per person")      \
  X(choice, DataLayout, layout, DataLayout::automatic, ,                                           \
    "a person's folder: ZJU-MoCap's (annots.npy) or EasyMocap's (intri.yml, extri.yml); auto "     \
    "tells them apart")                                                                            \
  X(key, int, person_id, -1, config::at_least(-1),                                                 \
    "easymocap: the person's id in the SMPL files; -1: the only one")                              \
  X(key, std::string, split_file, "data_splits/synthetic.yaml", {},                                \
    "people, frames and cameras per setting; empty: every person and frame under root")            \
  X(key, std::vector<std::string>, reference_views, {}, {},                                        \
    "fixed reference cameras by name or index, replacing the split's; empty: the split's, or "     \
    "without a split the num_reference_views cameras most evenly spread around the body")          \
  X(key, int, num_reference_views, 3, config::in(1, 64), "reference cameras without a split file") \
  X(key, std::string, train_setting, "training", {}, "the split's setting trained on")             \
  X(key, std::string, test_setting, "identity", {},                                                \
    "the split's setting evaluated: pose | identity | one_shot | cross_dataset | fitting")         \
  X(key, std::string, smpl_model, "", {}, "SMPL .pkl/.npz; empty: <root>/smpl_model.npz")          \
  X(key, double, ratio, 0.5, config::in(0.01, 1), "image resize factor (1024 px -> 512 px: 0.5)")  \
  X(choice, VisibilitySource, visibility, VisibilitySource::rasterize, ,                           \
    "vertex visibility per reference view: rasterized here, or read from NHP's files")             \
  X(key, std::string, visibility_root, "", {}, "visibility: files: the folder of the files")       \
  X(choice, MissingVisibility, visibility_missing, MissingVisibility::error, ,                     \
    "visibility: files: a missing file is an error, or all vertices visible (warns)")              \
  X(key, double, box_padding, 0.05, config::at_least(0),                                           \
    "the world box's padding on z, in metres (METHOD 2.2)")                                        \
  X(choice, CalibrationCheck, calibration_check, CalibrationCheck::error, ,                        \
    "calibration that cannot be right (intrinsics, rotations, the body out of a reference view "   \
    "or at an implausible distance): an error, or a warning")                                      \
  X(choice, BorderBand, border_band, BorderBand::distorted, ,                                      \
    "the target mask's border band (METHOD 2.1): marked before undistortion [parity], or after")   \
  X(section, PatchConfig, patch, , , "training rays (METHOD 5)")                                   \
  X(section, JitterConfig, jitter, , , "colour jitter (METHOD 2.1)")                               \
  X(key, int, workers, 2, config::in(0, 256), "background loader threads")                         \
  X(key, int, prefetch, 4, config::in(1, 1024), "samples queued ahead")
TH_CONFIG_SECTION(DataConfig, TH_DATA_KEYS)

// ---- model (METHOD 2.5, 3)
// What the retired execution keys of model.* (how the network was evaluated, never what it
// computes) say when a config still sets them.
inline constexpr const char* kRetiredExecutionKey =
    "the network always runs its fast forms (METHOD 9), chosen by device, precision and autograd";

#define TH_ENCODER_KEYS(X)                                             \
  X(key, std::string, pretrained, "", {},                              \
    "ResNet-18 weights (scripts/export_pretrained.py); empty: random") \
  X(choice, BatchNormStats, batchnorm, BatchNormStats::batch, ,        \
    "BatchNorm statistics: the batch's [parity] or running")           \
  X(retired, , fast_sampling, , , kRetiredExecutionKey)
TH_CONFIG_SECTION(EncoderConfig, TH_ENCODER_KEYS)

// model.grouping.kmeans_file's value that imports a reference checkpoint with token groups computed
// here instead of the reference's own (METHOD 8): its renders then differ from the reference's.
inline constexpr const char* kKMeansCompute = "compute";

#define TH_GROUPING_KEYS(X)                                                                    \
  X(choice, GroupingKind, kind, GroupingKind::canonical_kmeans, ,                              \
    "how SMPL's vertices are grouped into tokens (METHOD 3.2)")                                \
  X(key, int, num_tokens, 300, config::in(1, 6890),                                            \
    "Nt, the token count (SMPL has 6890 vertices)")                                            \
  X(key, std::string, kmeans_file, "", {},                                                     \
    "the reference's kmeans_dict_300.npy (needed to import its .pth), or compute; empty: the " \
    "labels stored with the model")                                                            \
  X(key, std::string, cache_dir, "cache", {},                                                  \
    "k-means labels cached here, keyed by body model and Nt")                                  \
  X(key, int64_t, seed, 0, {}, "k-means seed")                                                 \
  X(choice, MeanOver, mean_over, MeanOver::all, ,                                              \
    "a token's feature: mean over all its vertices [parity] or the visible ones")
TH_CONFIG_SECTION(GroupingConfig, TH_GROUPING_KEYS)

#define TH_TRANSHE_KEYS(X)                                                                      \
  X(key, bool, enabled, true, {}, "the transformer; false: tokens go straight to DPaRF")        \
  X(choice, TokenPosition, position, TokenPosition::canonical, ,                                \
    "the tokens' positional encoding: canonical centres, or posed (observation)")               \
  X(key, int, dim, 192, config::at_least(1), "token width")                                     \
  X(key, int, depth, 12, config::in(1, 64), "transformer blocks (enabled: false turns it off)") \
  X(key, int, heads, 3, config::at_least(1), "attention heads (must divide dim)")               \
  X(key, int, mlp_dim, 768, config::at_least(1), "the blocks' MLP width")                       \
  X(key, int, pe_freqs, 32, config::at_least(1), "positional-encoding frequencies (6 x = dim)") \
  X(key, double, pe_scale, 1.5, config::above(0), "Pc = mean(v_template[c]) / pe_scale")        \
  X(choice, PeRounding, pe_rounding, PeRounding::fused, ,                                       \
    "float32 sin(x f + phase): fused rounds once, as torch.addcmul [parity, METHOD 3.2]; "      \
    "separate rounds the product and the sum (numpy)")
TH_CONFIG_SECTION(TransHEConfig, TH_TRANSHE_KEYS)

#define TH_DPARF_KEYS(X)                                                                           \
  X(key, int, nk, 7, {}, "nearest fields per point (1..grouping.num_tokens)")                      \
  X(choice, Coordinate, coordinate, Coordinate::relative, ,                                        \
    "a point's coordinate in each field (METHOD 3.3)")                                             \
  X(key, double, softmax_temperature, 0.5, config::above(0), "w = softmax(-d / T)")                \
  X(key, int, pe_freqs, 10, config::at_least(0), "positional-encoding frequencies of coordinates") \
  X(choice, PeRounding, pe_rounding, PeRounding::fused, ,                                          \
    "fused [parity] | separate, as transhe.pe_rounding")
TH_CONFIG_SECTION(DPaRFConfig, TH_DPARF_KEYS)

#define TH_FDI_KEYS(X)                                                         \
  X(key, bool, appearance, true, {}, "a: the reference views' image features") \
  X(key, bool, human, true, {}, "h: the human representation branch")          \
  X(key, bool, raw_rgb, true, {}, "the reference pixels' colours in p_v")
TH_CONFIG_SECTION(FDIConfig, TH_FDI_KEYS)

#define TH_SPC_KEYS(X)                                            \
  X(key, double, voxel_size, 0.005 * 4, {},                       \
    "the grid's voxel in metres (representation: spc_trilinear)") \
  X(key, int, channels, 64, config::at_least(1), "the grid's feature channels")
TH_CONFIG_SECTION(SPCConfig, TH_SPC_KEYS)

#define TH_MODEL_KEYS(X)                                                  \
  X(choice, Representation, representation, Representation::transhuman, , \
    "transhuman, or spc_trilinear (the NHP-style baseline)")              \
  X(section, EncoderConfig, encoder, , , "image encoder (METHOD 2.5)")    \
  X(section, GroupingConfig, grouping, , , "token groups (METHOD 3.2)")   \
  X(section, TransHEConfig, transhe, , , "TransHE (METHOD 3.2)")          \
  X(section, DPaRFConfig, dparf, , , "DPaRF (METHOD 3.3)")                \
  X(section, FDIConfig, fdi, , , "FDI (METHOD 3.4)")                      \
  X(section, SPCConfig, spc, , , "the SPC + trilinear baseline")          \
  X(retired, , exact_shortcuts, , , kRetiredExecutionKey)                 \
  X(retired, , readout_windows, , , kRetiredExecutionKey)
TH_CONFIG_SECTION(ModelConfig, TH_MODEL_KEYS)

// ---- rendering (METHOD 4)
#define TH_RENDER_KEYS(X)                                                                         \
  X(key, int, samples, 64, config::in(2, 4096), "samples per ray (16: the paper's fast variant)") \
  X(key, bool, progressive, true, {},                                                             \
    "inference: distance culling, and colour only where the density is positive")                 \
  X(key, double, cull_distance, 0.1, config::above(0),                                            \
    "metres from the nearest body vertex beyond which a sample is empty")                         \
  X(key, int64_t, chunk_points, 4096, config::in(1024, 1 << 24),                                  \
    "per-point work in chunks of this many points (bench/results/model.md)")                      \
  X(key, double, termination_transmittance, 1e-4, config::in_below(0, 1),                         \
    "stop a ray once its transmittance is below this (changes rgb and acc by at most it); 0: "    \
    "every kept sample")                                                                          \
  X(key, int64_t, train_chunk_points, 4096, config::in(256, 1 << 24),                             \
    "training: the per-point network's chunk, recomputed in the backward pass")                   \
  X(choice, Recompute, train_recompute, Recompute::automatic, ,                                   \
    "training: always recompute each chunk in the backward pass (memory of one chunk), never "    \
    "(keep every chunk's graph), or auto (keep up to model::kKeepGraphPoints points per field "   \
    "call); the same weights bit for bit")
TH_CONFIG_SECTION(RenderConfig, TH_RENDER_KEYS)

// ---- training (METHOD 5)
#define TH_TRAIN_KEYS(X)                                                                        \
  X(key, int, epochs, 3000, config::in(1, 10000000), "epochs")                                  \
  X(key, int, iters_per_epoch, 500, config::in(1, 10000000), "steps per epoch")                 \
  X(key, double, lr, 7e-4, config::above(0), "peak learning rate")                              \
  X(key, double, min_lr, 1e-6, config::at_least(0), "the cosine schedule's floor (at most lr)") \
  X(key, int, warmup_epochs, 300, config::at_least(0), "linear warm-up (fewer than epochs)")    \
  X(key, double, beta1, 0.9, config::in_below(0, 1), "Adam's beta1")                            \
  X(key, double, beta2, 0.999, config::in_below(0, 1), "Adam's beta2")                          \
  X(key, double, eps, 1e-8, config::above(0), "Adam's epsilon")                                 \
  X(key, double, grad_clip, 40.0, config::above(0), "element-wise gradient clip")               \
  X(key, double, lpips_weight, 0.1, config::at_least(0), "the perceptual term's weight")        \
  X(key, std::string, lpips_weights, "", {},                                                    \
    "LPIPS weights (scripts/export_lpips.py); empty: the perceptual term is off")               \
  X(key, bool, skip_far_points, false, {},                                                      \
    "cull samples farther than render.cull_distance from the body in training too")             \
  X(key, int, save_every_epochs, 10, config::at_least(0),                                       \
    "checkpoint interval; 0: only at the end (latest.pt is always written)")                    \
  X(key, int, val_every_epochs, 10, config::at_least(0),                                        \
    "validation interval; 0: only after the last epoch")                                        \
  X(key, int, val_views, 2, config::in(0, 1024), "views rendered per validation")               \
  X(choice, ViewRenderer, val_renderer, ViewRenderer::exact, ,                                  \
    "validation views: exact (the network per sample) or baked (each frame baked at "           \
    "eval.bake_voxel, its views marched through the grid; METHOD 7.1)")                         \
  X(key, int, log_every_steps, 10, config::at_least(1), "metrics line interval")                \
  X(key, double, max_minutes, 0, config::at_least(0),                                           \
    "stop with a checkpoint after this wall time; 0: no limit")                                 \
  X(names, std::string, dist_backend, "auto", config::names("auto", "gloo", "nccl"),            \
    "several ranks: the c10d backend (auto: nccl on CUDA when built in, else gloo)")            \
  X(key, double, dist_timeout_s, 300, config::in_above(0, 86400),                               \
    "seconds a rank waits for the others before it stops with an error")                        \
  X(key, double, dist_bucket_mb, 25, config::in_above(0, 4096),                                 \
    "gradient all-reduce bucket size in MiB")                                                   \
  X(key, bool, sync_batchnorm, true, {},                                                        \
    "several ranks: the encoder's BatchNorm over every rank's images [parity]; false: each "    \
    "rank's own")
TH_CONFIG_SECTION(TrainConfig, TH_TRAIN_KEYS)

// ---- evaluation (METHOD 6)
#define TH_EVAL_KEYS(X)                                                                           \
  X(key, std::string, setting, "identity", {}, "the split's setting scored")                      \
  X(key, std::string, lpips_weights, "", {}, "LPIPS weights; empty: LPIPS is not scored")         \
  X(key, int, limit, 0, config::at_least(0), "images scored; 0: all")                             \
  X(key, bool, save_images, true, {}, "write each rendered view beside its scores")               \
  X(key, bool, reuse_frames, true, {},                                                            \
    "target views of one frame share its prepared stages (encoder, TransHE, DPaRF tokens); "      \
    "false: each view prepares its frame again")                                                  \
  X(choice, MismatchPolicy, model_mismatch, MismatchPolicy::error, ,                              \
    "a checkpoint trained with other model.* values: error names the keys and stops, warn names " \
    "them and goes on")                                                                           \
  X(choice, ViewRenderer, renderer, ViewRenderer::exact, ,                                        \
    "exact (the network per sample: the paper's protocol) or baked (each frame baked once, its "  \
    "views marched through the grid: an approximate score; METHOD 7.1)")                          \
  X(key, double, bake_voxel, 0.02, config::in(0.001, 0.2),                                        \
    "the baked renderer's lattice spacing, metres (eval.renderer and train.val_renderer baked)")
TH_CONFIG_SECTION(EvalConfig, TH_EVAL_KEYS)

// ---- the whole tree
#define TH_CONFIG_KEYS(X)                                                                       \
  X(key, int64_t, seed, 42, {}, "random seed")                                                  \
  X(names, std::string, device, "auto", config::names("auto", "cpu", "cuda"),                   \
    "where the network runs")                                                                   \
  X(choice, PrecisionChoice, precision, PrecisionChoice::fp32, ,                                \
    "the network's matrix products: fp32 (the paper's numbers), bf16, or auto (bf16 where the " \
    "processor has native bf16 dot products; model/precision.hpp)")                             \
  X(choice, Fp32Products, fp32_products, Fp32Products::automatic, ,                             \
    "fp32 products on CPU: auto (oneDNN when LibTorch has it), onednn or blas")                 \
  X(key, int, threads, 0, config::in(0, 4096), "CPU threads for LibTorch; 0: one per core")     \
  X(key, double, max_memory_gb, 0, config::at_least(0),                                         \
    "refuse work (render, mesh) estimated to need more; 0: 3/4 of physical memory")             \
  X(section, DataConfig, data, , , "data (METHOD 1, 2.1)")                                      \
  X(section, ModelConfig, model, , , "the network (METHOD 2.5, 3)")                             \
  X(section, RenderConfig, render, , , "rendering (METHOD 4)")                                  \
  X(section, TrainConfig, train, , , "training (METHOD 5)")                                     \
  X(section, EvalConfig, eval, , , "evaluation (METHOD 6)")
TH_CONFIG_SECTION(Config, TH_CONFIG_KEYS)

// Checks across fields (incompatible switches, one value bounded by another); throw th::Error.
void validate_section(const DataConfig& c, const std::string& path);
void validate_section(const ModelConfig& c, const std::string& path);
void validate_section(const TrainConfig& c, const std::string& path);

}  // namespace th
