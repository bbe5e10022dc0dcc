// The exact shortcuts of SPEC 9 against the direct computation they replace.
#include <catch2/catch.hpp>
#include <torch/torch.h>

#include "model/frame_fixture.hpp"
#include "model/sampling.hpp"
#include "model/transhuman.hpp"

using namespace th;
using namespace th::model;

namespace F = torch::nn::functional;

namespace {

double max_abs(const torch::Tensor& a, const torch::Tensor& b) {
  return (a - b).abs().max().item<double>();
}

torch::Tensor random_uv(int64_t n, int64_t V, int64_t W, int64_t H) {
  // Inside the image, on its border, and outside it (border padding).
  auto uv = torch::rand({n, V, 2}) * torch::tensor({W + 4.0, H + 4.0}) - 2;
  uv.index_put_({0}, torch::tensor({0.0, 0.0}));
  uv.index_put_({1}, torch::tensor({static_cast<double>(W - 1), static_cast<double>(H - 1)}));
  return uv;
}

}  // namespace

TEST_CASE("composed sampling equals grid_sample of the bilinearly upsampled map", "[model][sampling]") {
  torch::manual_seed(1);
  for (auto [h, w, H, W] : {std::array<int64_t, 4>{16, 16, 32, 32}, {8, 5, 31, 19}, {17, 9, 33, 17},
                            {32, 32, 32, 32}, {1, 3, 7, 9}}) {
    const int64_t V = 2, C = 5, n = 200;
    const auto map = torch::randn({V, C, h, w}, torch::kDouble);
    const auto up = F::interpolate(map, F::InterpolateFuncOptions()
                                            .size(std::vector<int64_t>{H, W})
                                            .mode(torch::kBilinear)
                                            .align_corners(true));
    const auto uv = random_uv(n, V, W, H).to(torch::kDouble);
    const auto direct = grid_sample_pixels(up, uv);  // (n, V, C)
    const auto flat = uv.reshape({-1, 2});
    const auto view = torch::arange(V).repeat({n});
    const auto taps = upsampled_bilinear_taps(flat, view, h, w, H, W);
    CHECK(taps.index.size(1) == (h == H && w == W ? 4 : 9));
    const auto fast = weighted_gather(to_table(map), taps).view({n, V, C});
    CHECK(max_abs(direct, fast) < 1e-12);
    // The one-pass CPU taps give the same taps as the tensor formulation.
    const auto cpu = multi_level_taps(flat, view, {{h, w}}, {0}, H, W);
    CHECK(torch::equal(cpu.index, taps.index));
    CHECK(torch::equal(cpu.weight, taps.weight));
    const auto cpu32 = multi_level_taps(flat.to(torch::kFloat), view, {{h, w}}, {0}, H, W);
    const auto ref32 = upsampled_bilinear_taps(flat.to(torch::kFloat), view, h, w, H, W);
    CHECK(torch::equal(cpu32.index, ref32.index));
    CHECK(torch::equal(cpu32.weight, ref32.weight));
  }
}

TEST_CASE("weighted gather backward equals index_select autograd", "[model][sampling]") {
  torch::manual_seed(2);
  const auto table = torch::randn({50, 7}, torch::kDouble).requires_grad_(true);
  Taps taps{torch::randint(0, 50, {30, 9}), torch::rand({30, 9}, torch::kDouble)};
  const auto g = torch::randn({30, 7}, torch::kDouble);
  const auto out = weighted_gather(table, taps);
  const auto ref = (table.index_select(0, taps.index.flatten()).view({30, 9, 7}) * taps.weight.unsqueeze(-1)).sum(1);
  CHECK(max_abs(out, ref) < 1e-12);
  const auto g1 = torch::autograd::grad({out}, {table}, {g})[0];
  const auto g2 = torch::autograd::grad({ref}, {table}, {g})[0];
  CHECK(max_abs(g1, g2) < 1e-12);
}

TEST_CASE("pixel readouts equal the linear layer on the materialised pixel feature", "[model][sampling]") {
  torch::manual_seed(3);
  for (bool raw_rgb : {true, false}) {
    EncoderConfig ec;
    Encoder enc(ec, raw_rgb);
    enc->eval();
    const int64_t V = 3, S = 32, n = 100;
    const auto images = torch::rand({V, 3, S, S});
    const auto views = enc->forward(images);
    const auto pf = enc->pixel_features(views);
    REQUIRE(pf.size(1) == enc->pixel_channels());
    torch::nn::Linear layer(enc->pixel_channels(), 40);
    const auto uv = random_uv(n, V, S, S);
    const auto direct = layer(grid_sample_pixels(pf, uv));
    const auto readout = enc->make_readout(views, layer->weight, layer->bias);
    const auto flat = uv.reshape({-1, 2});
    const auto view = torch::arange(V).repeat({n});
    const auto fast = readout.sample(views.geometry.stacked_level_taps(flat, view),
                                     views.geometry.image_taps(flat, view)).view({n, V, -1});
    CHECK(max_abs(direct, fast) < 2e-5 * (1 + direct.abs().max().item<double>()));
    // p_v itself, and painting, without materialising the pixel feature.
    const auto p = enc->sample_pixel_features(views, views.geometry.stacked_level_taps(flat, view),
                                              views.geometry.image_taps(flat, view));
    CHECK(max_abs(p.view({n, V, -1}), grid_sample_pixels(pf, uv)) < 2e-5);
    const auto vis = torch::rand({V, n}) < 0.7;
    const auto uvv = uv.permute({1, 0, 2});
    CHECK(max_abs(enc->paint(views, uvv, vis), enc->paint_direct(views, uvv, vis)) < 2e-5);
  }
}

TEST_CASE("the model with SPEC 9 shortcuts equals the direct computation", "[model][shortcuts]") {
  const auto frame = test::synthetic_frame();
  auto cfg = test::tiny_model_config();
  for (auto variant : {"default", "no_coordinate", "absolute", "wo_a", "wo_h", "wo_rgb", "spc"}) {
    DYNAMIC_SECTION(variant) {
      auto c = cfg;
      const std::string v = variant;
      if (v == "no_coordinate") c.dparf.coordinate = "none";
      if (v == "absolute") c.dparf.coordinate = "absolute";
      if (v == "wo_a") c.fdi.appearance = false;
      if (v == "wo_h") c.fdi.human = false;
      if (v == "wo_rgb") c.fdi.raw_rgb = false;
      if (v == "spc") c.representation = "spc_trilinear", c.spc.voxel_size = 0.1, c.spc.channels = 8;
      torch::manual_seed(4);
      TransHuman fast(c);
      auto cd = c;
      cd.exact_shortcuts = false;
      cd.encoder.fast_sampling = false;
      TransHuman direct(cd);
      {
        torch::NoGradGuard ng;
        auto src = fast->named_parameters();
        for (auto& p : direct->named_parameters()) p.value().copy_(src[p.key()]);
      }
      fast->eval();
      direct->eval();
      torch::NoGradGuard ng;
      const auto pts = frame.inputs.vertices.narrow(0, 0, 64) + 0.05 * torch::randn({64, 3});
      const auto dirs = torch::randn({64, 3});
      const auto a = fast->forward(fast->prepare(frame.inputs), pts, dirs);
      const auto b = direct->forward(direct->prepare(frame.inputs), pts, dirs);
      INFO("max |raw| " << b.abs().max().item<double>());
      CHECK(max_abs(a, b) < 1e-4 * (1 + b.abs().max().item<double>()));
    }
  }
}

TEST_CASE("the fused view-attention kernel equals bmm/softmax, values and gradients", "[model][shortcuts]") {
  torch::manual_seed(7);
  const int64_t n = 50, V = 3;
  auto q = torch::randn({n, V, 384}, torch::kDouble).requires_grad_(true);
  auto kv = torch::randn({n, V, 384}, torch::kDouble).requires_grad_(true);
  auto run = [&](bool fused) {
    const auto qq = q.narrow(2, 0, 128), k = kv.narrow(2, 0, 128), u = kv.narrow(2, 128, 256),
               r = q.narrow(2, 128, 256);
    return fused ? FDIImpl::attend(q, kv, 128) : torch::baddbmm(r, FDIImpl::attention(qq, k), u);
  };
  const auto g = torch::randn({n, V, 256}, torch::kDouble);
  const auto a = run(true), b = run(false);
  CHECK(max_abs(a, b) < 1e-12);
  const auto ga = torch::autograd::grad({a}, {q, kv}, {g});
  const auto gb = torch::autograd::grad({b}, {q, kv}, {g});
  CHECK(max_abs(ga[0], gb[0]) < 1e-12);
  CHECK(max_abs(ga[1], gb[1]) < 1e-12);
}

TEST_CASE("the one-pass DPaRF query equals the tensor formulation", "[model][shortcuts]") {
  torch::manual_seed(8);
  const int64_t nt = 60, n = 500;
  TokenFrames frames{torch::randn({nt, 3}) * 0.3, torch::eye(3).expand({nt, 3, 3}) + 0.2 * torch::randn({nt, 3, 3})};
  const auto xs = torch::randn({n, 3}) * 0.4;
  for (const char* coordinate : {"relative", "absolute", "none"}) {
    for (int nk : {1, 4, 7}) {
      DPaRFConfig cfg;
      cfg.coordinate = coordinate;
      cfg.nk = nk;
      DPaRF dparf(cfg);
      const auto a = dparf.query(frames, xs), b = dparf.query_tensors(frames, xs);
      INFO(coordinate << " nk " << nk);
      CHECK(torch::equal(a.index, b.index));
      CHECK(max_abs(a.weight, b.weight) < 1e-6);
      CHECK(a.coords.defined() == b.coords.defined());
      if (a.coords.defined()) CHECK(max_abs(a.coords, b.coords) < 1e-5);
    }
  }
}
