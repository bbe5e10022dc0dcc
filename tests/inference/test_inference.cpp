// Free-viewpoint rendering and mesh extraction from a (briefly trained) tiny checkpoint.
#include <torch/torch.h>
#include <unistd.h>

#include <catch2/catch.hpp>
#include <fstream>

#include "body/smpl.hpp"
#include "core/config_io.hpp"
#include "data/dataset.hpp"
#include "inference/free_view.hpp"
#include "inference/mesh_extraction.hpp"
#include "mesh/ply.hpp"
#include "model/transhuman.hpp"
#include "pipeline/checkpoint.hpp"
#include "pipeline/pipeline.hpp"
#include "support/test_env.hpp"
#include "train/trainer.hpp"
#include "video/camera_path.hpp"

namespace fs = std::filesystem;
using th::inference::VideoRequest;

namespace {

th::Config tiny_config() {
  const auto root = th::test::tiny_dataset();
  return th::config::load<th::Config>(
      "tests/configs/tiny_train.yaml",
      {"data.root=" + root.string(), "data.split_file=" + (root / "split.yaml").string(),
       "model.grouping.cache_dir=" + (root.parent_path() / "kmeans_cache").string(),
       "train.val_views=0", "eval.setting=identity"});
}

// A checkpoint trained for two steps, made once per process (CTest runs the test cases as
// parallel processes: each makes its own, in its own folder).
fs::path tiny_checkpoint() {
  static const fs::path checkpoint = [] {
    const fs::path run = th::test::scratch_dir("inference_ckpt_" + std::to_string(::getpid()));
    th::train::train(tiny_config(), torch::kCPU, {run, false, 2});
    return run / "checkpoints" / "latest.pt";
  }();
  return checkpoint;
}

}  // namespace

TEST_CASE("frame ranges: F, BEGIN:END, BEGIN:END:STEP, errors quote the text", "[inference]") {
  using th::inference::parse_frame_range;
  CHECK(parse_frame_range("12") == std::vector<int>{12});
  CHECK(parse_frame_range("0:4") == std::vector<int>{0, 1, 2, 3});
  CHECK(parse_frame_range("2:9:3") == std::vector<int>{2, 5, 8});
  for (const char* bad : {"", "a", "1:", "3:3", "0:4:0", "1:2:3:4", "1.5"})
    CHECK_THROWS_WITH(parse_frame_range(bad),
                      Catch::Contains("frame range '" + std::string(bad) + "'"));
}

TEST_CASE("a dataset camera renders the image evaluation renders, bit for bit", "[inference]") {
  const auto config = tiny_config();
  const th::inference::Session session(config, torch::kCPU, tiny_checkpoint());
  const int h = session.find_human("");
  const int frame = session.setting_frames(h).front();
  const auto prepared = session.prepare(h, frame, 5);
  const auto camera = session.dataset_camera(prepared, 5);
  const auto& s = prepared.sample;
  const auto image =
      session.render(prepared, camera, int(s.target_image.size(1)), int(s.target_image.size(0)));

  // transhuman-eval's path: the same sample through evaluate_view.
  th::model::TransHuman model(config.model);
  th::pipeline::load_weights(*model, tiny_checkpoint());
  model->eval();
  model->set_products(
      th::model::resolve_products(config.precision, config.fp32_products, torch::kCPU));
  const auto smpl = th::data::load_body_model(config.data);
  th::pipeline::Tokens tokens(*model, smpl->v_template);
  const auto inputs =
      th::pipeline::frame_inputs(s, smpl->v_template, tokens.labels(s.body), torch::kCPU);
  // Token positions come from v_template in float64, as the reference's do (METHOD 3.2 [parity]).
  CHECK(prepared.inputs.canonical.scalar_type() == torch::kDouble);
  const auto expected =
      th::pipeline::evaluate_view(*model, config.render, s, inputs, nullptr, torch::kCPU);
  CHECK(torch::equal(image, expected.pred));
  CHECK(image.max().item<float>() > 0);  // not an all-black comparison

  // A few rows at a time (how a large image keeps its memory bounded): the same pixels.
  const int width = int(s.target_image.size(1)), height = int(s.target_image.size(0));
  const auto banded = session.render(prepared, camera, width, height, int64_t(width) * 3);
  CHECK((banded - image).abs().max().item<float>() <= 1e-6f);
}

TEST_CASE(
    "too large renders and too fine mesh grids are refused before any work, with the estimate",
    "[inference]") {
  auto config = tiny_config();
  config.max_memory_gb = 1;
  const th::inference::Session session(config, torch::kCPU, tiny_checkpoint());
  const fs::path out = th::test::scratch_dir("inference_resources");
  th::inference::MeshRequest mesh;
  mesh.voxel = 1e-4;  // 7 billion grid points over the tiny person's box
  CHECK_THROWS_WITH(th::inference::extract_mesh(session, mesh, out / "mesh"),
                    Catch::Contains("mesh grid") && Catch::Contains("estimated peak memory") &&
                        Catch::Contains("max_memory_gb=1"));
  CHECK(!fs::exists(out / "mesh"));
  mesh.voxel = 0.01;
  mesh.threshold = -1;
  CHECK_THROWS_WITH(th::inference::extract_mesh(session, mesh, out / "mesh"),
                    Catch::Contains("mesh threshold must be a finite number >= 0, got -1"));

  VideoRequest r;
  r.width = 20000;
  r.height = 20000;
  CHECK_THROWS_WITH(
      th::inference::render_video(session, r, out / "video"),
      Catch::Contains("render 20000 x 20000 x 36 frames") && Catch::Contains("max_memory_gb"));
  CHECK(!fs::exists(out / "video" / "frames"));
}

TEST_CASE("an orbit over a frame range: frames, video, cameras, contact sheet, resumed and guarded",
          "[inference][video]") {
  const th::inference::Session session(tiny_config(), torch::kCPU, tiny_checkpoint());
  const fs::path out = th::test::scratch_dir("inference_orbit");
  VideoRequest request;
  request.frames = {0, 2};
  request.orbit_views = 3;
  request.width = 40;
  request.height = 48;
  const auto first = th::inference::render_video(session, request, out);
  CHECK(first.frames == 3);
  CHECK(first.rendered == 3);
  for (int k = 0; k < 3; ++k)
    CHECK(fs::exists(out / "frames" / ("frame_000" + std::to_string(k) + ".png")));
  CHECK(fs::exists(out / "contact_sheet.png"));
  if (first.video_written) CHECK(fs::file_size(out / "video.mp4") > 0);
  const auto path = th::video::read_camera_path(out / "cameras.yaml");
  CHECK(path.cameras.size() == 3);
  CHECK(path.width == 40);
  CHECK(path.height == 48);

  // Rerun: nothing left to render.
  fs::remove(out / "frames" / "frame_0001.png");
  const auto again = th::inference::render_video(session, request, out);
  CHECK(again.rendered == 1);
  CHECK(again.skipped == 2);

  // Another request into the same folder is refused, then forced.
  request.orbit_views = 4;
  CHECK_THROWS_WITH(
      th::inference::render_video(session, request, out),
      Catch::Contains("holds frames of another request") && Catch::Contains("--force"));
  request.force = true;
  CHECK(th::inference::render_video(session, request, out).rendered == 4);
  // Other weights, same request: the frames are not theirs.
  const fs::path other = th::test::scratch_dir("inference_other_ckpt") / "other.pt";
  fs::copy_file(tiny_checkpoint(), other);
  const th::inference::Session other_session(tiny_config(), torch::kCPU, other);
  request.force = false;
  CHECK_THROWS_WITH(th::inference::render_video(other_session, request, out),
                    Catch::Contains("holds frames of another request"));

  // The saved path renders again as a path file: the same images.
  VideoRequest replay;
  replay.cameras = VideoRequest::Cameras::PathFile;
  replay.path_file = out / "cameras.yaml";
  replay.frames = {0, 2};
  const fs::path out2 = th::test::scratch_dir("inference_replay");
  CHECK(th::inference::render_video(session, replay, out2).rendered == 4);
  for (int k = 0; k < 4; ++k) {
    const auto name = "frame_000" + std::to_string(k) + ".png";
    std::ifstream a(out / "frames" / name, std::ios::binary),
        b(out2 / "frames" / name, std::ios::binary);
    const std::string sa((std::istreambuf_iterator<char>(a)), {}),
        sb((std::istreambuf_iterator<char>(b)), {});
    CHECK(sa == sb);
  }
}

TEST_CASE(
    "frames are resumed only under the settings that made their pixels: another is named, or "
    "forced",
    "[inference][video]") {
  const fs::path out = th::test::scratch_dir("inference_settings");
  VideoRequest request;
  request.orbit_views = 2;
  request.width = 24;
  request.height = 24;
  const auto render = [&](const std::vector<std::string>& overrides) {
    auto config = tiny_config();
    YAML::Node tree = th::config::to_tree(config);
    for (const auto& o : overrides) th::config::apply_override(tree, o);
    config = th::config::from_tree<th::Config>(tree);
    const th::inference::Session session(config, torch::kCPU, tiny_checkpoint());
    return th::inference::render_video(session, request, out);
  };
  const auto frame = [&] {
    std::ifstream in(out / "frames" / "frame_0000.png", std::ios::binary);
    return std::string((std::istreambuf_iterator<char>(in)), {});
  };
  REQUIRE(render({}).rendered == 2);
  const std::string first = frame();
  // Each setting that changes pixels is named with the frames' value and the new one; nothing is
  // resumed and the frames stay as they were.
  const std::vector<std::pair<std::string, std::string>> changes{
      {"render.samples=4", "render.samples (frames: 8, now: 4)"},
      {"precision=bf16", "precision (frames: fp32"},
      {"render.progressive=false", "render.progressive (frames: true, now: false)"},
      {"model.dparf.softmax_temperature=0.25",
       "model.dparf.softmax_temperature (frames: 0.5, now: 0.25)"},
      {"data.ratio=0.125", "data.ratio (frames: 0.25, now: 0.125)"},
      {"eval.setting=pose", "eval.setting (frames: identity, now: pose)"}};
  for (const auto& [override_text, named] : changes) {
    CAPTURE(override_text);
    CHECK_THROWS_WITH(render({override_text, "eval.model_mismatch=warn"}),
                      Catch::Contains("holds frames of another request: ") &&
                          Catch::Contains(named) && Catch::Contains("--force"));
  }
  CHECK(frame() == first);
  // What does not change pixels resumes: threads, the loader, training-only keys, where caches
  // live.
  const auto resumed =
      render({"threads=2", "data.workers=2", "render.train_chunk_points=512", "train.lr=1e-3"});
  CHECK(resumed.rendered == 0);
  CHECK(resumed.skipped == 2);
  // --force renders them again under the new settings.
  request.force = true;
  CHECK(render({"render.samples=4"}).rendered == 2);
  CHECK(frame() != first);
  // frames/ without the request.yaml that says what made them: refused, not resumed.
  request.force = false;
  fs::remove(out / "request.yaml");
  CHECK_THROWS_WITH(render({"render.samples=4"}),
                    Catch::Contains("holds frames/ without the request.yaml"));
}

TEST_CASE("bad render requests name the person, frame or camera", "[inference][video]") {
  const th::inference::Session session(tiny_config(), torch::kCPU, tiny_checkpoint());
  const fs::path out = th::test::scratch_dir("inference_bad");
  VideoRequest r;
  r.human = "CoreView_nobody";
  CHECK_THROWS_WITH(th::inference::render_video(session, r, out),
                    Catch::Contains("CoreView_nobody") && Catch::Contains("CoreView_s03"));
  r.human = "";
  r.frames = {999};
  CHECK_THROWS_WITH(th::inference::render_video(session, r, out), Catch::Contains("frame 999"));
  r.frames = {};
  r.cameras = VideoRequest::Cameras::Dataset;
  r.camera = "99";
  CHECK_THROWS_WITH(th::inference::render_video(session, r, out), Catch::Contains("camera 99"));
}

TEST_CASE(
    "mesh of a frame: closed, inside the box, density culled away from the body, PLY and preview",
    "[inference][mesh]") {
  const th::inference::Session session(tiny_config(), torch::kCPU, tiny_checkpoint());
  const int h = session.find_human("");
  const auto prepared = session.prepare(h, 0, 3);

  // Points far from the body get zero density without the network.
  const auto far = prepared.sample.body.vertices.mean(0, true) + torch::tensor({{5.0f, 0.f, 0.f}});
  CHECK(session.density(prepared, far).item<float>() == 0.f);

  th::inference::MeshRequest request;
  request.voxel = 0.03;
  const auto sigma = session.density(prepared, prepared.sample.body.vertices);
  request.threshold = sigma.median().item<double>();  // a level the briefly trained net crosses
  request.colors = true;
  request.slab_points = 5000;  // many slabs
  const fs::path out = th::test::scratch_dir("inference_mesh");
  const auto m = th::inference::extract_mesh(session, request, out);
  REQUIRE(m.mesh.num_faces() > 0);
  CHECK(m.evaluated_points > 0);
  CHECK(m.evaluated_points < m.grid[0] * m.grid[1] * m.grid[2]);
  // Every edge shared by exactly two faces (closed).
  const auto f = m.mesh.faces;
  std::map<std::pair<int64_t, int64_t>, int> edges;
  auto a = f.accessor<int64_t, 2>();
  for (int64_t i = 0; i < f.size(0); ++i)
    for (int e = 0; e < 3; ++e) {
      const int64_t u = a[i][e], v = a[i][(e + 1) % 3];
      ++edges[{std::min(u, v), std::max(u, v)}];
    }
  size_t open = 0;
  for (const auto& [edge, n] : edges) open += n != 2;
  CHECK(open == 0);
  // World coordinates: inside the frame's box (grid padding adds one voxel at most).
  const auto box = prepared.sample.body.bounds.to(torch::kFloat32);
  CHECK((m.mesh.verts >= box[0] - 0.031f).all().item<bool>());
  CHECK((m.mesh.verts <= box[1] + 0.031f).all().item<bool>());
  const auto back = th::mesh::read_ply(m.ply);
  CHECK(torch::equal(back.verts, m.mesh.verts));
  CHECK(back.colors.defined());
  CHECK(fs::exists(m.preview));

  request.threshold = 1e9;
  CHECK_THROWS_WITH(th::inference::extract_mesh(session, request, out),
                    Catch::Contains("never exceeds the threshold"));
}
