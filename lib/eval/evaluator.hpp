#pragma once
// transhuman-eval's protocol (METHOD 6): every target view of a test setting rendered with fixed
// references, progressive rendering, PSNR / SSIM / LPIPS per image; per-image CSV, summary JSON,
// a markdown table, and for each image a panel (prediction, ground truth, inputs, error map).

#include <torch/types.h>

#include <filesystem>
#include <string>
#include <vector>

#include "core/config.hpp"

namespace th::dist {
class Communicator;
}

namespace th::eval {

struct ImageScore {
  std::string human;
  std::string renderer;  // "exact", or "baked 2 cm"
  int frame = 0, view = 0;
  double psnr = 0, ssim = 0, lpips = 0;  // lpips NaN when unavailable
  double seconds = 0;
  // Exact: rays x samples; of those, farther than render.cull_distance from the body; points
  // whose density the network computed. Baked: the samples looked up in the grid, 0, 0.
  int64_t points = 0, culled_points = 0, evaluated_points = 0;
  int64_t rays = 0, opaque_1e3 = 0, opaque_1e4 = 0;  // rays, and those opaque to 1e-3, 1e-4
};

struct EvalSummary {
  std::string setting;
  // What rendered the views: "exact" (the network at every sample: the paper's protocol) or
  // "baked <voxel> cm" (each frame baked once, its views marched through the grid; METHOD 7.1).
  std::string renderer = "exact";
  int64_t bakes = 0;  // frames baked (baked renderer)
  int images = 0;
  double psnr = 0, ssim = 0, lpips = 0;  // means; lpips NaN when unavailable
  bool lpips_available = false;
  double seconds_per_image = 0;
  // Of all rendered rays, the fractions whose final transmittance is below 1e-3 and 1e-4.
  double opaque_1e3 = 0, opaque_1e4 = 0;
  std::vector<ImageScore> per_image;
};

// Evaluates `checkpoint` (ours or a reference .pth) on config.eval.setting, writing results to
// `out_dir`. config.eval.limit > 0 evaluates only the first images. config.eval.renderer says
// how views are rendered: exact, or baked (eval.bake_voxel; one bake per frame, held while its
// views are scored). Every row says its renderer.
//
// `out_dir` gets request.yaml (the checkpoint, the renderer and every setting that changes a
// pixel) and rows.jsonl (each scored view as it comes). With `resume`, the views rows.jsonl
// holds are kept and only the others are evaluated, under the same request only: another one
// (another renderer, voxel, checkpoint or setting) is refused naming the keys that differ.
// Over several ranks every rank is given the same `resume`; rank 0 reads the rows and tells the
// others which views are left.
//
// With `comm` (several ranks), the views are split over the ranks by frame (the views of a
// frame share its preparation), balanced by estimated cost (shard_views); rank 0 receives every
// score and panel and writes exactly what one process writes, rows in the same order, and
// returns the summary; the other ranks write nothing and return their own rows only. A rank
// that fails or stops answering makes every rank fail, naming it, before anything but panels
// is written.
EvalSummary evaluate(const Config& config, const torch::Device& device,
                     const std::filesystem::path& checkpoint, const std::filesystem::path& out_dir,
                     dist::Communicator* comm = nullptr, bool resume = false);

// The check of evaluate(resume = true) alone, before anything is written (transhuman-eval runs
// it before its run folder is touched): th::Error unless `out_dir` holds a request.yaml equal to
// this evaluation's, naming the keys that differ.
void check_resume(const Config& config, const torch::Device& device,
                  const std::filesystem::path& checkpoint, const std::filesystem::path& out_dir);

// Which of a setting's first `n` items each of `ranks` ranks evaluates: the items of one
// (person, frame) stay together when `reuse_frames` (their preparation is shared), each frame
// costing its views plus a preparation of a quarter view; whole frames go largest first to the
// least loaded rank.
std::vector<std::vector<int64_t>> shard_views(const std::vector<std::pair<int, int>>& item_frames,
                                              bool reuse_frames, int ranks);

// The file name of an image's panel in <out_dir>/images: "<human>_f<frame:04>_v<view:02>.png".
std::string panel_file_name(const std::string& human, int frame, int view);

// "| setting | renderer | images | PSNR | SSIM | LPIPS |" rows for a set of summaries.
std::string markdown_table(const std::vector<EvalSummary>& summaries);

}  // namespace th::eval
