#include "eval/evaluator.hpp"

#include <spdlog/spdlog.h>
#include <torch/torch.h>

#include <cmath>
#include <fstream>
#include <map>
#include <optional>
#include <sstream>

#include "body/smpl.hpp"
#include "core/error.hpp"
#include "core/progress.hpp"
#include "data/dataset.hpp"
#include "dist/communicator.hpp"
#include "dist/shard.hpp"
#include "io/files.hpp"
#include "metrics/lpips.hpp"
#include "pipeline/checkpoint.hpp"
#include "pipeline/images.hpp"
#include "pipeline/jsonl.hpp"
#include "pipeline/pipeline.hpp"
#include "video/frame_writer.hpp"

namespace th::eval {
namespace fs = std::filesystem;

namespace {

std::string fmt(double v, int digits) {
  if (!std::isfinite(v)) return "n/a";
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.*f", digits, v);
  return buf;
}

// A CSV field (RFC 4180): quoted, with its quotes doubled, when it holds a comma, a quote or a
// line break (a person's folder name may).
std::string csv_field(const std::string& text) {
  if (text.find_first_of(",\"\r\n") == std::string::npos) return text;
  std::string out = "\"";
  for (const char c : text) out += c == '"' ? std::string("\"\"") : std::string(1, c);
  return out + "\"";
}

// Each file is written whole or not at all (a full disk names the file that failed).
void write_outputs(const EvalSummary& s, const fs::path& dir) {
  std::ostringstream csv;
  csv << "human,frame,view,psnr,ssim,lpips,seconds,points,culled_points,evaluated_points\n";
  for (const auto& r : s.per_image)
    csv << csv_field(r.human) << ',' << r.frame << ',' << r.view << ',' << fmt(r.psnr, 6) << ','
        << fmt(r.ssim, 6) << ',' << fmt(r.lpips, 6) << ',' << fmt(r.seconds, 3) << ',' << r.points
        << ',' << r.culled_points << ',' << r.evaluated_points << '\n';
  io::write_file_atomic(dir / "per_image.csv", csv.str());
  pipeline::JsonLine j;
  j.add("setting", s.setting)
      .add("images", s.images)
      .add("psnr", s.psnr)
      .add("ssim", s.ssim)
      .add("lpips", s.lpips)
      .add("lpips_available", std::string(s.lpips_available ? "yes" : "no"))
      .add("seconds_per_image", s.seconds_per_image)
      .add("opaque_rays_1e-3", s.opaque_1e3)
      .add("opaque_rays_1e-4", s.opaque_1e4);
  io::write_file_atomic(dir / "summary.json", j.str() + "\n");
  io::write_file_atomic(dir / "results.md", markdown_table({s}));
}

}  // namespace

std::string panel_file_name(const std::string& human, int frame, int view) {
  char name[32];
  std::snprintf(name, sizeof name, "_f%04d_v%02d.png", frame, view);
  return human + name;
}

std::string markdown_table(const std::vector<EvalSummary>& summaries) {
  std::string out = "| setting | images | PSNR | SSIM | LPIPS |\n|---|---|---|---|---|\n";
  for (const auto& s : summaries)
    out += "| " + s.setting + " | " + std::to_string(s.images) + " | " + fmt(s.psnr, 2) + " | " +
           fmt(s.ssim, 3) + " | " + (s.lpips_available ? fmt(s.lpips, 3) : "n/a (no weights)") +
           " |\n";
  return out;
}

std::vector<std::vector<int64_t>> shard_views(const std::vector<std::pair<int, int>>& item_frames,
                                              bool reuse_frames, int ranks) {
  constexpr double kPreparation = 0.25;  // a frame's preparation, in views (512x512, 64 samples)
  std::vector<std::vector<int64_t>> groups;
  std::map<std::pair<int, int>, size_t> group_of;
  for (size_t i = 0; i < item_frames.size(); ++i) {
    if (!reuse_frames) {
      groups.push_back({int64_t(i)});
      continue;
    }
    const auto [it, added] = group_of.emplace(item_frames[i], groups.size());
    if (added) groups.emplace_back();
    groups[it->second].push_back(int64_t(i));
  }
  std::vector<double> cost;
  for (const auto& g : groups) cost.push_back(double(g.size()) + kPreparation);
  return dist::balance(groups, cost, ranks);
}

EvalSummary evaluate(const Config& config, const torch::Device& device, const fs::path& checkpoint,
                     const fs::path& out_dir, dist::Communicator* comm) {
  const std::string setting = config.eval.setting;
  const auto smpl = data::load_body_model(config.data);
  auto dataset =
      std::make_shared<const data::Dataset>(config.data, setting, data::Dataset::Mode::Test, smpl);
  dataset->require_targets();
  model::TransHuman model(config.model);
  pipeline::load_weights(*model, checkpoint, config.eval.model_mismatch == MismatchPolicy::warn);
  model->to(device);
  model->eval();
  model->set_products(model::select_products(config.precision, config.fp32_products, device));
  auto lpips = metrics::try_load_lpips(config.eval.lpips_weights, device, "the LPIPS metric");
  const torch::Tensor canonical = smpl->v_template;   // float64: token positions [parity]
  pipeline::Tokens tokens(*model, smpl->v_template);  // the checkpoint's token groups

  size_t n = dataset->size();
  if (config.eval.limit > 0) n = std::min(n, size_t(config.eval.limit));
  const int ranks = comm ? comm->world_size() : 1, rank = comm ? comm->rank() : 0;
  std::vector<std::pair<int, int>> item_frames;
  for (size_t i = 0; i < n; ++i)
    item_frames.emplace_back(dataset->item(i).human, dataset->item(i).frame);
  const auto assignment = shard_views(item_frames, config.eval.reuse_frames, ranks);
  const auto& mine = assignment[size_t(rank)];
  std::vector<size_t> order(mine.begin(), mine.end());
  data::Prefetcher loader(dataset, order, std::vector<uint64_t>(order.size(), 0),
                          config.data.workers, config.data.prefetch);
  const fs::path image_dir = out_dir / "images";
  const bool writes = !out_dir.empty();
  if (config.eval.save_images && writes) fs::create_directories(image_dir);
  if (ranks > 1) spdlog::info("eval: {} views over {} ranks ({} here)", n, ranks, mine.size());

  // One view: its scores and counts, and its panel's PNG bytes, as a record (sent to rank 0 by
  // the others).
  pipeline::FrameReuse frames;
  auto work = [&](int64_t item) {
    const data::Sample s = loader.next();
    TORCH_CHECK(s.human == dataset->humans()[size_t(dataset->item(size_t(item)).human)]->name() &&
                    s.frame == dataset->item(size_t(item)).frame,
                "eval: the loader is out of step with the assignment at item ", item);
    const auto inputs = pipeline::frame_inputs(s, canonical, tokens.labels(s.body), device);
    pipeline::ViewResult r;
    try {
      r = pipeline::evaluate_view(*model, config.render, s, inputs, lpips.get(), device,
                                  config.eval.reuse_frames ? &frames : nullptr);
    } catch (const Error& e) {
      fail("checkpoint '", checkpoint.string(), "', ", e.what());
    }
    std::string panel;
    if (config.eval.save_images) {
      std::vector<cv::Mat> imgs{video::to_bgr8(r.pred), video::to_bgr8(r.gt)};
      std::vector<std::string> captions{"prediction " + fmt(r.psnr, 2) + " dB", "ground truth"};
      for (int64_t v = 0; v < s.ref_images.size(0); ++v) {
        imgs.push_back(video::to_bgr8(s.ref_images[v].permute({1, 2, 0})));
        captions.push_back("input view " + std::to_string(s.reference_views[size_t(v)]));
      }
      imgs.push_back(pipeline::error_map(r.pred, r.gt));
      captions.push_back("|error|");
      panel = video::encode_png(pipeline::panel(imgs, captions),
                                "the panel of " + s.human + " frame " + std::to_string(s.frame));
    }
    dist::Record rec;
    rec.put(s.human).put(int64_t(s.frame)).put(int64_t(s.target_view));
    rec.put(r.psnr).put(r.ssim).put(r.lpips).put(r.seconds);
    rec.put(r.stats.points).put(r.stats.culled_points).put(r.stats.density_points);
    rec.put(r.rays).put(r.opaque_1e3).put(r.opaque_1e4).put(panel);
    return rec.bytes();
  };

  EvalSummary summary;
  summary.setting = setting;
  summary.lpips_available = lpips != nullptr;
  std::vector<std::optional<ImageScore>> rows(n);
  int64_t rays = 0, opaque_1e3 = 0, opaque_1e4 = 0;
  Progress progress("eval " + setting, int64_t(rank == 0 ? n : mine.size()), "img");
  auto collect = [&](int64_t item, const std::string& bytes) {
    dist::Record rec(bytes);
    ImageScore score;
    score.human = rec.text("person");
    score.frame = int(rec.int64("frame"));
    score.view = int(rec.int64("view"));
    score.psnr = rec.number("PSNR");
    score.ssim = rec.number("SSIM");
    score.lpips = rec.number("LPIPS");
    score.seconds = rec.number("seconds");
    score.points = rec.int64("points");
    score.culled_points = rec.int64("culled points");
    score.evaluated_points = rec.int64("evaluated points");
    rays += rec.int64("rays");
    opaque_1e3 += rec.int64("rays opaque to 1e-3");
    opaque_1e4 += rec.int64("rays opaque to 1e-4");
    const std::string panel = rec.text("panel");
    if (!panel.empty() && writes)
      io::write_file_atomic(image_dir / panel_file_name(score.human, score.frame, score.view),
                            panel);
    char note[64];
    std::snprintf(note, sizeof note, "PSNR %.2f SSIM %.3f", score.psnr, score.ssim);
    rows.at(size_t(item)) = std::move(score);
    progress.advance(1, note);
  };

  // Rank 0 (or the only process), once every row is in: the summary and the three files.
  auto finish = [&] {
    progress.finish();
    if (config.eval.reuse_frames)
      spdlog::info("eval: {} frames prepared for {} views (eval.reuse_frames{})", frames.prepared(),
                   frames.prepared() + frames.reused(), ranks > 1 ? ", on this rank" : "");
    for (auto& row : rows) {
      TORCH_CHECK(row.has_value(), "eval: a view's result is missing after every rank finished");
      summary.per_image.push_back(std::move(*row));
    }
    summary.images = int(summary.per_image.size());
    summary.opaque_1e3 = rays ? double(opaque_1e3) / double(rays) : 0.0;
    summary.opaque_1e4 = rays ? double(opaque_1e4) / double(rays) : 0.0;
    spdlog::info("eval: {} rays, final transmittance below 1e-3 on {:.4f}%, below 1e-4 on {:.4f}%",
                 rays, 100 * summary.opaque_1e3, 100 * summary.opaque_1e4);
    if (summary.images == 0) fail("setting '", setting, "' has no images to evaluate");
    auto mean = [&](auto field) {
      double sum = 0;
      for (const auto& r : summary.per_image) sum += field(r);
      return sum / summary.images;
    };
    summary.psnr = mean([](const ImageScore& r) { return r.psnr; });
    summary.ssim = mean([](const ImageScore& r) { return r.ssim; });
    summary.lpips = lpips ? mean([](const ImageScore& r) { return r.lpips; }) : NAN;
    summary.seconds_per_image = mean([](const ImageScore& r) { return r.seconds; });
    if (writes) write_outputs(summary, out_dir);
    spdlog::info("{}: {} images | PSNR {:.2f} | SSIM {:.4f} | LPIPS {} | {:.1f} s/image", setting,
                 summary.images, summary.psnr, summary.ssim,
                 lpips ? fmt(summary.lpips, 4) : "n/a (no weights)", summary.seconds_per_image);
  };

  if (comm) {
    comm->sharded(assignment, work, collect, finish, "the evaluation of " + setting);
  } else {
    for (const int64_t item : mine) collect(item, work(item));
    finish();
  }
  return summary;
}

}  // namespace th::eval
