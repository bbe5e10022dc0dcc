#include "eval/evaluator.hpp"

#include <spdlog/spdlog.h>
#include <torch/torch.h>
#include <yaml-cpp/yaml.h>

#include <cmath>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <optional>
#include <sstream>
#include <tuple>

#include "bake/bake.hpp"
#include "body/smpl.hpp"
#include "core/error.hpp"
#include "core/progress.hpp"
#include "data/dataset.hpp"
#include "dist/communicator.hpp"
#include "dist/shard.hpp"
#include "inference/request.hpp"
#include "inference/session.hpp"
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
  csv << "human,frame,view,psnr,ssim,lpips,seconds,points,culled_points,evaluated_points,"
         "renderer\n";
  for (const auto& r : s.per_image)
    csv << csv_field(r.human) << ',' << r.frame << ',' << r.view << ',' << fmt(r.psnr, 6) << ','
        << fmt(r.ssim, 6) << ',' << fmt(r.lpips, 6) << ',' << fmt(r.seconds, 3) << ',' << r.points
        << ',' << r.culled_points << ',' << r.evaluated_points << ',' << csv_field(r.renderer)
        << '\n';
  io::write_file_atomic(dir / "per_image.csv", csv.str());
  pipeline::JsonLine j;
  j.add("setting", s.setting)
      .add("renderer", s.renderer)
      .add("images", s.images)
      .add("psnr", s.psnr)
      .add("ssim", s.ssim)
      .add("lpips", s.lpips)
      .add("lpips_available", std::string(s.lpips_available ? "yes" : "no"))
      .add("seconds_per_image", s.seconds_per_image)
      .add("opaque_rays_1e-3", s.opaque_1e3)
      .add("opaque_rays_1e-4", s.opaque_1e4);
  if (s.bakes) j.add("frames_baked", s.bakes);
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
  std::string out =
      "| setting | renderer | images | PSNR | SSIM | LPIPS |\n|---|---|---|---|---|---|\n";
  for (const auto& s : summaries)
    out += "| " + s.setting + " | " + s.renderer + " | " + std::to_string(s.images) + " | " +
           fmt(s.psnr, 2) + " | " + fmt(s.ssim, 3) + " | " +
           (s.lpips_available ? fmt(s.lpips, 3) : "n/a (no weights)") + " |\n";
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

namespace {

// What makes two evaluations' rows interchangeable (request.yaml): the checkpoint, the setting,
// the renderer (with its voxel) and every setting that changes a pixel.
std::string describe(const Config& config, const torch::Device& device,
                     const std::string& checkpoint_id, const std::string& renderer) {
  YAML::Emitter y;
  y << YAML::BeginMap << YAML::Key << "checkpoint" << YAML::Value << checkpoint_id;
  y << YAML::Key << "setting" << YAML::Value << config.eval.setting;
  y << YAML::Key << "renderer" << YAML::Value << renderer;
  if (config.eval.renderer == ViewRenderer::baked)
    y << YAML::Key << "bake.voxel" << YAML::Value << fmt(config.eval.bake_voxel, 4);
  y << YAML::Key << "settings" << YAML::Value;
  inference::emit_pixel_settings(y, config, device);
  y << YAML::EndMap;
  return std::string(y.c_str()) + "\n";
}

// A scored view as a line of rows.jsonl, and back.
std::string row_line(int64_t item, const ImageScore& r) {
  return pipeline::JsonLine()
             .add("item", item)
             .add("human", r.human)
             .add("frame", r.frame)
             .add("view", r.view)
             .add("renderer", r.renderer)
             .add("psnr", r.psnr)
             .add("ssim", r.ssim)
             .add("lpips", r.lpips)
             .add("seconds", r.seconds)
             .add("points", r.points)
             .add("culled_points", r.culled_points)
             .add("evaluated_points", r.evaluated_points)
             .add("rays", r.rays)
             .add("opaque_1e3", r.opaque_1e3)
             .add("opaque_1e4", r.opaque_1e4)
             .str() +
         "\n";
}

// The rows of an earlier run's rows.jsonl that belong to the views now evaluated (`items`: the
// dataset's (person name, frame, view) of each view index). A line cut short by a stop is
// dropped with a warning (its view is evaluated again); any other line that does not read, or
// names a view the setting does not have at that index, is an error naming the file and line.
// `setting_views`: the setting's views without eval.limit (the file's size is bounded by them).
// Returns the lines kept (every row read, a line cut short left out), for the file to be
// written again before rows are appended to it.
std::string read_rows(const fs::path& file,
                      const std::vector<std::tuple<std::string, int, int>>& items,
                      const std::string& renderer, std::vector<std::optional<ImageScore>>& rows,
                      size_t setting_views) {
  // A row is a few hundred bytes: a file far beyond the setting's views is not this folder's.
  constexpr uintmax_t kBytesPerRow = 4096;
  const uintmax_t bytes = fs::file_size(file);
  if (bytes > kBytesPerRow * (setting_views + 16))
    fail("'", file.string(), "' holds ", bytes, " bytes, more than ", setting_views,
         " rows can (at most ", kBytesPerRow,
         " bytes each): not this evaluation's rows; remove it "
         "to evaluate every view again, or --force");
  const std::string text = io::read_file(file);
  std::stringstream in(text);
  std::string line;
  int number = 0;
  int64_t beyond = 0;
  std::string kept;
  while (std::getline(in, line)) {
    ++number;
    if (line.empty()) continue;
    const std::string where = "'" + file.string() + "' line " + std::to_string(number);
    nlohmann::json j;
    try {
      j = nlohmann::json::parse(line);
    } catch (const nlohmann::json::exception&) {
      if (in.peek() == EOF && text.back() != '\n') {
        spdlog::warn(
            "eval: {} was cut short (the run stopped while writing it): its view is "
            "evaluated again",
            where);
        continue;
      }
      fail(where,
           " is not a JSON object: remove the folder's rows.jsonl to evaluate every view "
           "again, or --force");
    }
    ImageScore r;
    int64_t item = -1;
    try {
      item = j.at("item").get<int64_t>();
      r.human = j.at("human").get<std::string>();
      r.frame = j.at("frame").get<int>();
      r.view = j.at("view").get<int>();
      r.renderer = j.at("renderer").get<std::string>();
      auto number_or_nan = [&](const char* key) {
        const auto& v = j.at(key);
        return v.is_null() ? NAN : v.get<double>();
      };
      r.psnr = number_or_nan("psnr");
      r.ssim = number_or_nan("ssim");
      r.lpips = number_or_nan("lpips");
      r.seconds = number_or_nan("seconds");
      r.points = j.at("points").get<int64_t>();
      r.culled_points = j.at("culled_points").get<int64_t>();
      r.evaluated_points = j.at("evaluated_points").get<int64_t>();
      r.rays = j.at("rays").get<int64_t>();
      r.opaque_1e3 = j.at("opaque_1e3").get<int64_t>();
      r.opaque_1e4 = j.at("opaque_1e4").get<int64_t>();
    } catch (const nlohmann::json::exception& e) {
      fail(where, " is not a row of scores (", e.what(), ")");
    }
    if (!std::isfinite(r.psnr) || !std::isfinite(r.ssim))
      fail(where, ": its PSNR or SSIM is not a finite number");
    if (r.renderer != renderer)
      fail(where, " was rendered by '", r.renderer, "', not '", renderer, "'");
    if (item < 0) fail(where, ": item ", item, " is negative");
    kept += line + "\n";
    if (item >= int64_t(items.size())) {
      ++beyond;  // a larger eval.limit before
      continue;
    }
    const auto& [human, frame, view] = items[size_t(item)];
    if (r.human != human || r.frame != frame || r.view != view)
      fail(where, " scores ", r.human, " frame ", r.frame, " view ", r.view, " as view ", item,
           ", where the setting now has ", human, " frame ", frame, " view ", view,
           ": evaluate in another folder, or --force");
    rows[size_t(item)] = std::move(r);
  }
  if (beyond)
    spdlog::info("eval: {} rows of {} lie beyond eval.limit and are left out of this summary",
                 beyond, file.string());
  return kept;
}

}  // namespace

void check_resume(const Config& config, const torch::Device& device, const fs::path& checkpoint,
                  const fs::path& out_dir) {
  const fs::path request_file = out_dir / "request.yaml";
  if (!fs::exists(request_file))
    fail("cannot resume the evaluation in '", out_dir.string(),
         "': it holds no request.yaml (it is not an evaluation's folder, or one that never "
         "started); use another --out, or --force to evaluate anew");
  const std::string renderer = bake::renderer_label(config.eval.renderer, config.eval.bake_voxel);
  const std::string before = io::read_file(request_file);
  const std::string wanted =
      describe(config, device, inference::checkpoint_identity(checkpoint), renderer);
  if (before == wanted) return;
  const std::string changed = inference::request_differences(before, wanted, "rows");
  fail("cannot resume the evaluation in '", out_dir.string(),
       "': its rows were made by another request", changed.empty() ? "" : ": " + changed, " (see ",
       request_file.string(), "); use another --out, or --force to evaluate anew");
}

EvalSummary evaluate(const Config& config, const torch::Device& device, const fs::path& checkpoint,
                     const fs::path& out_dir, dist::Communicator* comm, bool resume) {
  const std::string setting = config.eval.setting;
  const bool baked = config.eval.renderer == ViewRenderer::baked;
  const std::string renderer = bake::renderer_label(config.eval.renderer, config.eval.bake_voxel);
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
  const std::string checkpoint_id = inference::checkpoint_identity(checkpoint);
  // The baked renderer: the same network, its frames baked through a session over it.
  std::unique_ptr<inference::Session> session;
  std::unique_ptr<bake::SampleBakes> bakes;
  if (baked) {
    session = std::make_unique<inference::Session>(config, device, model, dataset, canonical,
                                                   checkpoint_id);
    bake::BakeOptions options;
    options.voxel = config.eval.bake_voxel;
    bakes = std::make_unique<bake::SampleBakes>(*session, options);
  }

  size_t n = dataset->size();
  if (config.eval.limit > 0) n = std::min(n, size_t(config.eval.limit));
  const int ranks = comm ? comm->world_size() : 1, rank = comm ? comm->rank() : 0;
  const fs::path image_dir = out_dir / "images";
  const bool writes = !out_dir.empty();
  if (config.eval.save_images && writes) fs::create_directories(image_dir);

  // The rows an earlier run of the same request scored (rank 0 reads them), and the views left.
  std::vector<std::optional<ImageScore>> rows(n);
  std::ofstream journal;
  const fs::path journal_file = out_dir / "rows.jsonl";
  if (writes) {
    const fs::path request_file = out_dir / "request.yaml";
    const std::string wanted = describe(config, device, checkpoint_id, renderer);
    if (resume) {
      check_resume(config, device, checkpoint, out_dir);
      std::vector<std::tuple<std::string, int, int>> items;
      for (size_t i = 0; i < n; ++i) {
        const auto& it = dataset->item(i);
        items.emplace_back(dataset->humans()[size_t(it.human)]->name(), it.frame, it.target_view);
      }
      io::write_file_atomic(journal_file,
                            fs::exists(journal_file)
                                ? read_rows(journal_file, items, renderer, rows, dataset->size())
                                : std::string());
    } else {
      io::write_file_atomic(request_file, wanted);
      io::write_file_atomic(journal_file, "");
    }
    journal.open(journal_file, std::ios::app);
    if (!journal) fail("cannot append to '", journal_file.string(), "'");
  }
  std::vector<int64_t> todo;
  for (size_t i = 0; i < n; ++i)
    if (!rows[i]) todo.push_back(int64_t(i));
  if (comm && resume)  // rank 0 read the rows: which views are left is its to say
    dist::broadcast_items(*comm, todo, "the views left to evaluate");
  if (resume && rank == 0)
    spdlog::info("eval: resumed: {} of {} views already scored, {} left", n - todo.size(), n,
                 todo.size());
  std::vector<std::pair<int, int>> item_frames;
  for (const int64_t i : todo)
    item_frames.emplace_back(dataset->item(size_t(i)).human, dataset->item(size_t(i)).frame);
  // A bake serves every view of its frame: the baked renderer keeps a frame's views together.
  auto assignment = shard_views(item_frames, config.eval.reuse_frames || baked, ranks);
  for (auto& list : assignment)
    for (auto& index : list) index = todo[size_t(index)];
  const auto& mine = assignment[size_t(rank)];
  std::vector<size_t> order(mine.begin(), mine.end());
  data::Prefetcher loader(dataset, order, std::vector<uint64_t>(order.size(), 0),
                          config.data.workers, config.data.prefetch);
  if (ranks > 1) spdlog::info("eval: {} views over {} ranks ({} here)", n, ranks, mine.size());
  // A frame's bake colours its points as seen from the cameras of its views scored here.
  std::map<std::pair<int, int>, std::vector<std::array<double, 3>>> frame_eyes;
  if (baked) {
    for (const size_t i : order) {
      const auto& it = dataset->item(i);
      const auto& camera = dataset->humans()[size_t(it.human)]->camera(it.target_view);
      frame_eyes[{it.human, it.frame}].push_back(bake::camera_centre(camera.R, camera.T));
    }
    spdlog::info("eval: views {} (eval.renderer baked, eval.bake_voxel {} m): one bake per frame",
                 renderer, config.eval.bake_voxel);
  }

  // One view: its scores and counts, and its panel's PNG bytes, as a record (sent to rank 0 by
  // the others).
  pipeline::FrameReuse frames;
  auto work = [&](int64_t item) {
    const data::Sample s = loader.next();
    TORCH_CHECK(s.human == dataset->humans()[size_t(dataset->item(size_t(item)).human)]->name() &&
                    s.frame == dataset->item(size_t(item)).frame,
                "eval: the loader is out of step with the assignment at item ", item);
    pipeline::ViewResult r;
    try {
      if (bakes) {
        const auto& it = dataset->item(size_t(item));
        const auto view = bakes->render(s, frame_eyes.at({it.human, it.frame}));
        r = pipeline::score_view(view.ray_rgb, view.ray_acc, s, lpips.get(), device);
        r.seconds = view.bake_seconds + view.march_seconds;
        r.stats.points = view.stats.samples;
      } else {
        const auto inputs = pipeline::frame_inputs(s, canonical, tokens.labels(s.body), device);
        r = pipeline::evaluate_view(*model, config.render, s, inputs, lpips.get(), device,
                                    config.eval.reuse_frames ? &frames : nullptr);
      }
    } catch (const Error& e) {
      fail("checkpoint '", checkpoint.string(), "', ", e.what());
    }
    std::string panel;
    if (config.eval.save_images) {
      std::vector<cv::Mat> imgs{video::to_bgr8(r.pred), video::to_bgr8(r.gt)};
      std::vector<std::string> captions{
          (baked ? renderer + " " : "prediction ") + fmt(r.psnr, 2) + " dB", "ground truth"};
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
  summary.renderer = renderer;
  summary.lpips_available = lpips != nullptr;
  Progress progress("eval " + setting, int64_t(rank == 0 ? todo.size() : mine.size()), "img");
  auto collect = [&](int64_t item, const std::string& bytes) {
    dist::Record rec(bytes);
    ImageScore score;
    score.human = rec.text("person");
    score.renderer = renderer;
    score.frame = int(rec.int64("frame"));
    score.view = int(rec.int64("view"));
    score.psnr = rec.number("PSNR");
    score.ssim = rec.number("SSIM");
    score.lpips = rec.number("LPIPS");
    score.seconds = rec.number("seconds");
    score.points = rec.int64("points");
    score.culled_points = rec.int64("culled points");
    score.evaluated_points = rec.int64("evaluated points");
    score.rays = rec.int64("rays");
    score.opaque_1e3 = rec.int64("rays opaque to 1e-3");
    score.opaque_1e4 = rec.int64("rays opaque to 1e-4");
    const std::string panel = rec.text("panel");
    if (!panel.empty() && writes)
      io::write_file_atomic(image_dir / panel_file_name(score.human, score.frame, score.view),
                            panel);
    if (journal.is_open()) {
      journal << row_line(item, score) << std::flush;
      if (!journal) fail("cannot append to '", journal_file.string(), "' (disk full?)");
    }
    char note[64];
    std::snprintf(note, sizeof note, "PSNR %.2f SSIM %.3f", score.psnr, score.ssim);
    rows.at(size_t(item)) = std::move(score);
    progress.advance(1, note);
  };

  // Rank 0 (or the only process), once every row is in: the summary and the three files.
  auto finish = [&] {
    progress.finish();
    if (bakes)
      spdlog::info("eval: {} frames baked for {} views ({})", bakes->bakes(), bakes->views(),
                   renderer);
    else if (config.eval.reuse_frames)
      spdlog::info("eval: {} frames prepared for {} views (eval.reuse_frames{})", frames.prepared(),
                   frames.prepared() + frames.reused(), ranks > 1 ? ", on this rank" : "");
    summary.bakes = bakes ? bakes->bakes() : 0;
    int64_t rays = 0, opaque_1e3 = 0, opaque_1e4 = 0;
    for (auto& row : rows) {
      TORCH_CHECK(row.has_value(), "eval: a view's result is missing after every rank finished");
      rays += row->rays;
      opaque_1e3 += row->opaque_1e3;
      opaque_1e4 += row->opaque_1e4;
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
    spdlog::info("{} ({}): {} images | PSNR {:.2f} | SSIM {:.4f} | LPIPS {} | {:.2f} s/image",
                 setting, renderer, summary.images, summary.psnr, summary.ssim,
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
