// Baked frames (METHOD 7.1): the file, the ray march against the exact renderer, the bake against
// the network, and the viewer's frame caches.
#include <sys/stat.h>
#include <torch/torch.h>
#include <unistd.h>

#include <catch2/catch.hpp>
#include <cmath>
#include <fstream>

#include "bake/bake.hpp"
#include "bake/baked_frame.hpp"
#include "bake/march.hpp"
#include "core/config_io.hpp"
#include "data/rays.hpp"
#include "render/volume.hpp"
#include "support/test_env.hpp"
#include "support/tiny_config.hpp"
#include "train/trainer.hpp"
#include "viewer/recent.hpp"

namespace fs = std::filesystem;
using th::bake::BakedFrame;

namespace {

// Density a + b.p, and colour c0 + C p / sigma(p): the density and the density times the colour
// are linear in the position, so that a grid holding them at its lattice points gives them
// exactly anywhere the density is positive, by trilinear interpolation of the density and the
// density-weighted interpolation of the colour (METHOD 7.1); with C = 0 the colour is one
// everywhere and the density may cross zero.
struct LinearField {
  double a = -2.0, b[3] = {3.0, 1.0, 2.0};
  double c0[3] = {0.5, 0.4, 0.6}, C[3][3] = {{0, 0, 0}, {0, 0, 0}, {0, 0, 0}};
  double sigma(const double p[3]) const { return a + b[0] * p[0] + b[1] * p[1] + b[2] * p[2]; }
  double color(int ch, const double p[3]) const {
    return c0[ch] + (C[ch][0] * p[0] + C[ch][1] * p[1] + C[ch][2] * p[2]) / sigma(p);
  }
};

// The same field for the exact renderer: rgb logits whose sigmoid is the colour.
class LinearRadiance : public th::render::RadianceField {
 public:
  explicit LinearRadiance(const LinearField& f) : f_(f) {}
  torch::Tensor raw(const torch::Tensor& pts, const torch::Tensor&) override {
    const auto p = pts.to(torch::kFloat64);
    auto out = torch::zeros({p.size(0), 4}, torch::kFloat64);
    const auto x = p.select(1, 0), y = p.select(1, 1), z = p.select(1, 2);
    const auto sigma = f_.a + f_.b[0] * x + f_.b[1] * y + f_.b[2] * z;
    for (int ch = 0; ch < 3; ++ch) {
      const auto c = f_.c0[ch] + (f_.C[ch][0] * x + f_.C[ch][1] * y + f_.C[ch][2] * z) / sigma;
      out.select(1, ch).copy_(torch::log(c / (1 - c)));
    }
    out.select(1, 3).copy_(sigma);
    return out.to(pts.scalar_type());
  }

 private:
  LinearField f_;
};

// A grid over `box` (padded by 0.01 as the bake pads it) holding `field` at every lattice point,
// every brick stored; colour where the density is positive, black elsewhere (as a bake leaves it).
BakedFrame linear_grid(const LinearField& field, const std::array<double, 6>& box, double voxel,
                       int brick) {
  BakedFrame g;
  g.human = "linear";
  g.checkpoint = "none";
  g.voxel = voxel;
  g.brick = brick;
  g.box = box;
  for (int a = 0; a < 3; ++a) {
    g.origin[a] = box[a] - 0.01;
    g.cells[a] = int64_t(std::ceil((box[3 + a] - box[a] + 0.02) / voxel));
  }
  const auto nb = g.bricks();
  const int64_t P = brick + 1;
  for (int64_t bi = 0; bi < nb[0]; ++bi)
    for (int64_t bj = 0; bj < nb[1]; ++bj)
      for (int64_t bk = 0; bk < nb[2]; ++bk) {
        g.slot.push_back(int32_t(g.slot.size()));
        for (int64_t i = 0; i < P; ++i)
          for (int64_t j = 0; j < P; ++j)
            for (int64_t k = 0; k < P; ++k) {
              const double p[3] = {g.origin[0] + double(bi * brick + i) * voxel,
                                   g.origin[1] + double(bj * brick + j) * voxel,
                                   g.origin[2] + double(bk * brick + k) * voxel};
              const double sigma = field.sigma(p);
              g.density.push_back(float(sigma));
              for (int ch = 0; ch < 3; ++ch)
                g.color.push_back(sigma > 0 ? float(field.color(ch, p)) : 0.0f);
            }
      }
  return g;
}

}  // namespace

TEST_CASE("the march of a grid equals the exact renderer on a field the grid holds exactly",
          "[bake]") {
  // One colour and a density crossing zero: the black of the points outside the body must not
  // show. Then a positive density and a colour varying with it.
  LinearField varying;
  varying.a = 0.5;  // sigma >= 0.9 in the box
  varying.C[0][0] = 0.1, varying.C[1][1] = -0.1, varying.C[1][2] = 0.05;
  varying.C[2][0] = 0.05, varying.C[2][1] = 0.05;
  const auto field = GENERATE_COPY(LinearField{}, varying);
  const std::array<double, 6> box{-0.3, -0.2, 0.8, 0.25, 0.35, 1.3};
  const auto grid = linear_grid(field, box, 0.05, 4);  // several bricks per axis
  // A camera at the origin looking down +z, a 24 x 20 image.
  const auto K = torch::tensor({30.0, 0.0, 12.0, 0.0, 30.0, 10.0, 0.0, 0.0, 1.0}, torch::kFloat64)
                     .view({3, 3});
  const auto R = torch::eye(3, torch::kFloat64), T = torch::zeros({3, 1}, torch::kFloat64);
  th::bake::MarchOptions march;
  march.samples = 24;
  march.termination = 0;  // every sample, as the exact renderer
  const auto baked = th::bake::render_baked(grid, K, R, T, 24, 20, march);

  const auto pixels = th::data::pixel_grid(24, 20);
  const auto rays = th::data::pixel_rays(pixels, K, R, T);
  const auto box_t =
      torch::tensor({box[0], box[1], box[2], box[3], box[4], box[5]}, torch::kFloat64).view({2, 3});
  const auto nf = th::data::near_far(rays.origins, rays.dirs, box_t);
  const auto valid = nf.valid;
  REQUIRE(valid.sum().item<int64_t>() > 100);
  CHECK(baked.stats.rays == valid.sum().item<int64_t>());
  const th::render::Rays r{rays.origins.index({valid}), rays.dirs.index({valid}),
                           nf.near.index({valid}), nf.far.index({valid})};
  th::RenderConfig rc;
  rc.samples = march.samples;
  rc.chunk_points = 1 << 20;
  LinearRadiance exact_field(field);
  torch::NoGradGuard no_grad;
  const auto exact = th::render::VolumeRenderer(rc).render(exact_field, r, false);
  const auto flat = baked.rgb.view({-1, 3}).index({valid});
  CHECK((flat.to(torch::kFloat64) - exact.rgb).abs().max().item<double>() < 1e-4);
  CHECK((baked.acc.flatten().index({valid}).to(torch::kFloat64) - exact.acc)
            .abs()
            .max()
            .item<double>() < 1e-4);
  CHECK((baked.depth.flatten().index({valid}).to(torch::kFloat64) - exact.depth)
            .abs()
            .max()
            .item<double>() < 1e-4);
  // Rays that miss the box stay black.
  CHECK(baked.rgb.view({-1, 3}).index({valid.logical_not()}).abs().sum().item<double>() == 0);
  CHECK(exact.acc.max().item<double>() > 0.5);  // the field is seen, not empty
}

TEST_CASE("a baked frame survives its file, and a damaged file is refused naming it", "[bake]") {
  const auto grid = linear_grid(LinearField{}, {0, 0, 0, 0.1, 0.1, 0.1}, 0.05, 2);
  const fs::path dir = th::test::scratch_dir("bake_file_" + std::to_string(::getpid()));
  const fs::path file = dir / "frame.thbake";
  th::bake::write_baked(grid, file);
  const auto back = th::bake::read_baked(file);
  CHECK(back.density == grid.density);
  CHECK(back.color == grid.color);
  CHECK(back.slot == grid.slot);
  CHECK(back.cells == grid.cells);
  CHECK(back.origin == grid.origin);
  CHECK(back.human == "linear");

  std::string bytes;
  {
    std::ifstream in(file, std::ios::binary);
    bytes.assign(std::istreambuf_iterator<char>(in), {});
  }
  auto damaged = [&](const std::string& name, const std::string& content) {
    const fs::path p = dir / name;
    std::ofstream(p, std::ios::binary) << content;
    return p;
  };
  const auto refused = [](const fs::path& p, const std::string& why) {
    CHECK_THROWS_WITH(th::bake::read_baked(p), Catch::Contains(p.string()) && Catch::Contains(why));
  };
  refused(damaged("truncated.thbake", bytes.substr(0, bytes.size() - 5)), "truncated");
  refused(damaged("magic.thbake", "PNG" + bytes.substr(3)), "not a baked frame");
  std::string version = bytes;
  version[8] = 9;
  refused(damaged("version.thbake", version), "format version 9");
  // A slot used twice: the second brick takes the first one's slot.
  const size_t header = 16 + size_t(uint8_t(bytes[12])) + 256 * size_t(uint8_t(bytes[13]));
  std::string twice = bytes;
  std::memcpy(&twice[header + 4], &twice[header], 4);
  refused(damaged("twice.thbake", twice), "used twice");
  std::string nan = bytes;
  const float bad = std::nanf("");
  std::memcpy(&nan[bytes.size() - 4], &bad, 4);
  refused(damaged("nan.thbake", nan), "not finite");
  refused(dir / "missing.thbake", "cannot open");
  // A header longer than any bake's, and arrays above a memory bound, before they are read.
  std::string long_header = bytes;
  const uint32_t huge = uint32_t{1} << 30;
  std::memcpy(&long_header[12], &huge, 4);
  refused(damaged("long_header.thbake", long_header), "more than a baked frame's");
  CHECK_THROWS_WITH(th::bake::read_baked(file, 16.0),
                    Catch::Contains(file.string()) && Catch::Contains("max_memory_gb"));
  // What is not a file is refused without being opened for long: a FIFO would block a read.
  const fs::path fifo = dir / "fifo.thbake";
  REQUIRE(::mkfifo(fifo.c_str(), 0600) == 0);
  refused(fifo, "FIFO");
  CHECK_THROWS_WITH(th::bake::read_baked("/dev/zero"), Catch::Contains("character device"));
  // A bake file is a new file: never written over one, nor where another appeared.
  CHECK_THROWS_WITH(th::bake::write_baked(grid, file), Catch::Contains("exists"));
  CHECK(th::bake::read_baked(file).density == grid.density);
}

TEST_CASE("a bake's destination is checked before the bake", "[bake]") {
  const fs::path dir = th::test::scratch_dir("bake_out_" + std::to_string(::getpid()));
  fs::create_directories(dir / "out");
  fs::create_directories(dir / "data");
  const std::vector<std::pair<std::string, std::string>> places{
      {"--out", (dir / "out").string()}, {"the data root (data.root)", (dir / "data").string()}};
  const auto refused = [&](const fs::path& p, const std::string& why) {
    CHECK_THROWS_WITH(th::bake::check_bake_destination(p, "--bake-out", places),
                      Catch::Contains("--bake-out '" + p.string() + "'") && Catch::Contains(why));
  };
  th::bake::check_bake_destination(dir / "new.thbake", "--bake-out", places);
  refused(dir / "missing" / "f.thbake", "does not exist");
  refused(dir / "out" / "config.yaml", "lies in --out");
  refused(dir / "data" / "f.thbake", "lies in the data root (data.root)");
  std::ofstream(dir / "taken.thbake") << "x";
  refused(dir / "taken.thbake", "exists");
}

TEST_CASE("a bake holds the network's density and colour at its lattice points", "[bake]") {
  const fs::path run = th::test::scratch_dir("bake_ckpt_" + std::to_string(::getpid()));
  th::train::train(th::test::tiny_train_config({"train.val_views=0", "eval.setting=identity"}),
                   torch::kCPU, {run, false, 2});
  const th::inference::Session session(
      th::test::tiny_train_config(
          {"train.val_views=0", "eval.setting=identity", "max_memory_gb=2"}),
      torch::kCPU, run / "checkpoints" / "latest.pt");
  const auto frame = session.prepare(0, session.setting_frames(0).front(), 0);
  th::bake::BakeOptions options;
  options.voxel = 0.05;
  options.coarse = 1;  // every lattice point asked of the network in the first pass
  options.brick = 4;
  th::bake::BakeReport report;
  const auto baked = th::bake::bake_frame(session, frame, options, &report);
  REQUIRE(baked.stored_bricks() > 0);
  // Every stored lattice point, with its world position.
  const auto nb = baked.bricks();
  const int64_t P = options.brick + 1;
  std::vector<double> positions;
  std::vector<int64_t> rows;
  for (int64_t b = 0; b < int64_t(baked.slot.size()); ++b) {
    if (baked.slot[size_t(b)] < 0) continue;
    const int64_t bi = b / (nb[1] * nb[2]), bj = (b / nb[2]) % nb[1], bk = b % nb[2];
    for (int64_t l = 0; l < P * P * P; ++l) {
      const int64_t i = bi * options.brick + l / (P * P), j = bj * options.brick + (l / P) % P,
                    k = bk * options.brick + l % P;
      if (i > baked.cells[0] || j > baked.cells[1] || k > baked.cells[2]) continue;  // padding
      positions.insert(positions.end(), {baked.origin[0] + double(i) * baked.voxel,
                                         baked.origin[1] + double(j) * baked.voxel,
                                         baked.origin[2] + double(k) * baked.voxel});
      rows.push_back(baked.slot[size_t(b)] * P * P * P + l);
    }
  }
  const auto pts = torch::tensor(positions, torch::kFloat64).view({-1, 3});
  const auto idx = torch::tensor(rows, torch::kInt64);
  const auto stored_density = torch::tensor(baked.density, torch::kFloat32).index_select(0, idx);
  const auto density = session.density(frame, pts);
  CHECK((stored_density - density).abs().max().item<double>() <
        1e-4 * std::max(1.0, density.abs().max().item<double>()));
  // Colour where the density is positive: the mean over the six axis directions.
  const auto positive = density.gt(0).nonzero().flatten();
  REQUIRE(positive.size(0) > 0);
  const auto dirs = torch::tensor({1.0, 0.0, 0.0, -1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, -1.0, 0.0,
                                   0.0, 0.0, 1.0, 0.0, 0.0, -1.0},
                                  torch::kFloat32)
                        .view({6, 3});
  const auto seen = session.colors_along(frame, pts.index_select(0, positive), dirs);
  const auto stored_color = torch::tensor(baked.color, torch::kFloat32)
                                .view({-1, 3})
                                .index_select(0, idx.index_select(0, positive));
  CHECK((stored_color - seen.rgb.mean(0)).abs().max().item<double>() < 1e-5);
  // ... and the colours of one direction are those of the full forward pass.
  const auto one = session.color(frame, pts.index_select(0, positive),
                                 dirs[2].unsqueeze(0).expand({positive.size(0), 3}));
  CHECK((one - seen.rgb[2]).abs().max().item<double>() < 1e-5);

  // A bake for two cameras: the same density, and a colour set per eye, each the network's
  // colour seen from that camera's centre along the direction to the point.
  auto for_eyes = options;
  for_eyes.eyes = {{0.3, -2.5, 1.2}, {-1.8, 0.4, 0.9}};
  const auto eyed = th::bake::bake_frame(session, frame, for_eyes);
  REQUIRE(eyed.color_sets() == 2);
  REQUIRE(eyed.slot == baked.slot);
  CHECK((torch::tensor(eyed.density) - torch::tensor(baked.density)).abs().max().item<double>() <
        1e-6);
  const auto seen_pts = pts.index_select(0, positive);
  const auto eyed_color = torch::tensor(eyed.color, torch::kFloat32)
                              .view({-1, 2, 3})
                              .index_select(0, idx.index_select(0, positive));
  for (int k = 0; k < 2; ++k) {
    const auto eye = torch::tensor(
        {for_eyes.eyes[size_t(k)][0], for_eyes.eyes[size_t(k)][1], for_eyes.eyes[size_t(k)][2]},
        torch::kFloat64);
    const auto from_eye = session.color(frame, seen_pts, seen_pts - eye);
    CHECK((eyed_color.select(1, k) - from_eye).abs().max().item<double>() < 1e-5);
  }
  CHECK((eyed_color.select(1, 0) - eyed_color.select(1, 1)).abs().max().item<double>() > 1e-3);
  // Each set marches on its own; a set the bake lacks, and writing the bake, are refused.
  const auto cam0 = session.dataset_camera(frame, 0);
  auto march = th::bake::MarchOptions{};
  const auto set0 = th::bake::render_baked(eyed, cam0.K, cam0.R, cam0.T, 32, 24, march);
  march.color_set = 1;
  const auto set1 = th::bake::render_baked(eyed, cam0.K, cam0.R, cam0.T, 32, 24, march);
  CHECK(torch::equal(set0.acc, set1.acc));
  CHECK(!torch::equal(set0.rgb, set1.rgb));
  march.color_set = 2;
  CHECK_THROWS(th::bake::render_baked(eyed, cam0.K, cam0.R, cam0.T, 32, 24, march));
  CHECK_THROWS_WITH(th::bake::write_baked(eyed, run / "eyed.thbake"),
                    Catch::Contains("a colour per camera (2 cameras)"));
  CHECK(!fs::exists(run / "eyed.thbake"));
  // A video through the baked renderer: what BakedViews renders is the march of this bake.
  th::bake::BakedViews views(session, options);
  const auto cam = session.dataset_camera(frame, 0);
  const auto image = views.render(frame, cam, 32, 24);
  const auto direct =
      th::bake::render_baked(views.bake(frame), cam.K, cam.R, cam.T, 32, 24, views.march());
  CHECK(torch::equal(image, direct.rgb));

  // The lattice over a box, counted by hand: extents padded by 0.01 on each side (0.12, 0.22,
  // 0.32 m) in whole coarse cells of 2 cm, 6, 11 and 16, so 12, 22 and 32 cells of 1 cm.
  th::bake::BakeOptions fine;
  fine.voxel = 0.01;
  const std::array<double, 6> box{0, 0, 0, 0.1, 0.2, 0.3};
  const auto e = th::bake::bake_estimate(box, fine, session, "a box");
  CHECK_THAT(e.what, Catch::Contains("--bake-voxel 0.01 m (lattice 13 x 23 x 33)"));
  fine.voxel = 0.005;
  const double chunk =
      double(session.config().render.chunk_points) * th::resources::kBytesPerChunkPoint;
  const double ratio =
      (th::bake::bake_estimate(box, fine, session, "a box").bytes - chunk) / (e.bytes - chunk);
  // Between the growth of the lattice padded to bricks of 8, 25 x 49 x 65 / (17 x 25 x 33) = 5.7,
  // and of the lattice itself, 25 x 45 x 65 / (13 x 23 x 33) = 7.4.
  CHECK(ratio > 5.6);
  CHECK(ratio < 7.5);
  // A millimetre grid over the frame's box is refused before anything is allocated.
  fine.voxel = 0.001;
  CHECK_THROWS_WITH(th::bake::bake_frame(session, frame, fine),
                    Catch::Contains("--bake-voxel 0.001 m") &&
                        Catch::Contains("estimated peak memory") &&
                        Catch::Contains("max_memory_gb=2"));
}

TEST_CASE("the viewer's frame caches evict the least recently used frame", "[viewer]") {
  th::viewer::Recent<int, std::string> cache(2);
  cache.put(1, "one");
  cache.put(2, "two");
  REQUIRE(cache.find(1) != nullptr);  // 1 is now the most recent
  cache.put(3, "three");              // 2 goes, not the smallest key
  CHECK(cache.find(2) == nullptr);
  CHECK(*cache.find(1) == "one");
  CHECK(*cache.find(3) == "three");
  cache.put(3, "again");  // replacing keeps the size
  CHECK(cache.size() == 2);
  CHECK(*cache.find(3) == "again");
}
