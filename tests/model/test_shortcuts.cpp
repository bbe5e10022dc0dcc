// The exact shortcuts of METHOD 9 and the kernels that read them, against the direct computation
// they replace (grid_sample of the upsampled maps, the layers on p_v) and against their LibTorch
// forms.
#include <torch/torch.h>

#include <algorithm>
#include <array>
#include <catch2/catch.hpp>
#include <cmath>

#include "geometry/camera.hpp"
#include "model/frame_fixture.hpp"
#include "model/kernels/encoding.hpp"
#include "model/kernels/forms.hpp"
#include "model/kernels/nearest_fields.hpp"
#include "model/kernels/view_attention.hpp"
#include "model/kernels/view_mean.hpp"
#include "model/pixels.hpp"
#include "model/transhuman.hpp"

using namespace th;
using namespace th::model;

namespace F = torch::nn::functional;

using test::grid_sample_pixels;
using test::max_abs;

namespace {

torch::Tensor random_uv(int64_t n, int64_t V, int64_t W, int64_t H) {
  // Inside the image, on its border, and outside it (border padding).
  auto uv = torch::rand({n, V, 2}) * torch::tensor({W + 4.0, H + 4.0}) - 2;
  uv.index_put_({0}, torch::tensor({0.0, 0.0}));
  uv.index_put_({1}, torch::tensor({static_cast<double>(W - 1), static_cast<double>(H - 1)}));
  return uv;
}

}  // namespace

TEST_CASE("composed sampling equals grid_sample of the bilinearly upsampled map",
          "[model][sampling]") {
  torch::manual_seed(1);
  for (auto [h, w, H, W] : {std::array<int64_t, 4>{16, 16, 32, 32},
                            {8, 5, 31, 19},
                            {17, 9, 33, 17},
                            {32, 32, 32, 32},
                            {1, 3, 7, 9}}) {
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
    const kernels::TapLayout layout{{{h, w}}, {0}, H, W};
    const auto libtorch_taps = [&](const torch::Tensor& at) {
      kernels::LibTorchForms libtorch_forms;
      return kernels::level_taps(at, view, layout);
    };
    const auto taps = libtorch_taps(flat);
    CHECK(taps.index.size(1) == (h == H && w == W ? 4 : 9));
    const auto fast = kernels::weighted_gather(to_table(map), taps).view({n, V, C});
    CHECK(max_abs(direct, fast) < 1e-12);
    // The one-pass CPU taps give the same taps as the LibTorch form.
    const auto cpu = kernels::level_taps(flat, view, layout);
    CHECK(torch::equal(cpu.index, taps.index));
    CHECK(torch::equal(cpu.weight, taps.weight));
    const auto cpu32 = kernels::level_taps(flat.to(torch::kFloat), view, layout);
    const auto ref32 = libtorch_taps(flat.to(torch::kFloat));
    CHECK(torch::equal(cpu32.index, ref32.index));
    CHECK(torch::equal(cpu32.weight, ref32.weight));
  }
}

TEST_CASE("weighted gather backward equals index_select autograd", "[model][sampling]") {
  torch::manual_seed(2);
  const auto table = torch::randn({50, 7}, torch::kDouble).requires_grad_(true);
  Taps taps{torch::randint(0, 50, {30, 9}), torch::rand({30, 9}, torch::kDouble)};
  const auto g = torch::randn({30, 7}, torch::kDouble);
  const auto out = kernels::weighted_gather(table, taps);
  const auto ref =
      (table.index_select(0, taps.index.flatten()).view({30, 9, 7}) * taps.weight.unsqueeze(-1))
          .sum(1);
  CHECK(max_abs(out, ref) < 1e-12);
  const auto g1 = torch::autograd::grad({out}, {table}, {g})[0];
  const auto g2 = torch::autograd::grad({ref}, {table}, {g})[0];
  CHECK(max_abs(g1, g2) < 1e-12);
}

TEST_CASE("the gather's epilogue equals its operations done after the gather",
          "[model][sampling]") {
  torch::manual_seed(3);
  const int64_t M = 40, G = 8;
  const auto table = torch::randn({60, 3 * G}, torch::kDouble).requires_grad_(true);
  const auto addend = torch::randn({M, G}, torch::kDouble).requires_grad_(true);
  const Taps taps{torch::randint(0, 60, {M, 4}), torch::rand({M, 4}, torch::kDouble)};
  const auto g = torch::randn({M, 3 * G}, torch::kDouble);
  // The CPU kernel against the LibTorch form: addend on each group of G channels, then the clamp.
  const auto fused = kernels::weighted_gather(table, taps, {}, {addend, true, c10::nullopt});
  torch::Tensor ref;
  {
    kernels::LibTorchForms forms;
    ref = kernels::weighted_gather(table, taps, {}, {addend, true, c10::nullopt});
  }
  const auto plain =
      (kernels::weighted_gather(table, taps).view({M, 3, G}) + addend.unsqueeze(1)).relu();
  CHECK(max_abs(fused, plain.view({M, -1})) < 1e-12);
  CHECK(max_abs(fused, ref) < 1e-12);
  CHECK((fused == 0).any().item<bool>());  // the clamp acts
  const auto ga = torch::autograd::grad({fused}, {table, addend}, {g});
  const auto gb = torch::autograd::grad({ref}, {table, addend}, {g});
  CHECK(max_abs(ga[0], gb[0]) < 1e-12);
  CHECK(max_abs(ga[1], gb[1]) < 1e-12);
  // bf16 rows: the fp32 rows rounded once, to the bit; gradients in fp32.
  const auto t32 = table.detach().to(torch::kFloat).requires_grad_(true);
  const auto a32 = addend.detach().to(torch::kFloat);
  const auto rows32 = kernels::weighted_gather(t32, taps, {}, {a32, true, c10::nullopt});
  const auto rows16 = kernels::weighted_gather(t32, taps, {}, {a32, true, torch::kBFloat16});
  CHECK(rows16.scalar_type() == torch::kBFloat16);
  CHECK(torch::equal(rows16, rows32.to(torch::kBFloat16)));
  const auto g16 = torch::autograd::grad({rows16}, {t32}, {g.to(torch::kBFloat16)})[0];
  const auto g32 =
      torch::autograd::grad({rows32}, {t32}, {g.to(torch::kBFloat16).to(torch::kFloat)})[0];
  CHECK(g16.scalar_type() == torch::kFloat);
  CHECK(max_abs(g16, g32) < 1e-6);
  // A bf16 table (the readout windows under bf16): each value widened as it is read, the sums in
  // fp32, fp32 or bf16 rows; the same as the widened table's, to the bit.
  const auto t16 = t32.detach().to(torch::kBFloat16), widened = t16.to(torch::kFloat);
  for (const auto dtype :
       {c10::optional<c10::ScalarType>(), c10::make_optional(torch::kBFloat16)}) {
    const kernels::GatherEpilogue epilogue{a32, true, dtype};
    const auto rows = kernels::weighted_gather(t16, taps, {}, epilogue);
    CHECK(rows.scalar_type() == dtype.value_or(torch::kFloat));
    CHECK(torch::equal(rows, kernels::weighted_gather(widened, taps, {}, epilogue)));
    kernels::LibTorchForms forms;
    CHECK(max_abs(kernels::weighted_gather(t16, taps, {}, epilogue),
                  kernels::weighted_gather(widened, taps, {}, epilogue)) == 0);
  }
  CHECK_THROWS_WITH(kernels::weighted_gather(t16.clone().requires_grad_(true), taps),
                    Catch::Contains("a bf16 table is read only"));
  // A float64 table writes no bf16 rows.
  CHECK_THROWS_WITH(
      kernels::weighted_gather(table.detach(), taps, {}, {{}, false, torch::kBFloat16}),
      Catch::Contains("bf16 from fp32 sums"));
}

TEST_CASE("pixel readouts equal the linear layer on the materialised pixel feature",
          "[model][sampling]") {
  torch::manual_seed(3);
  for (bool raw_rgb : {true, false}) {
    EncoderConfig ec;
    Encoder enc(ec, raw_rgb, 192);
    enc->eval();
    const int64_t V = 3, S = 32, n = 100;
    const auto images = torch::rand({V, 3, S, S});
    const auto views = enc->forward(images);
    const auto pf = test::pixel_feature_map(views.levels, views.images, enc->upsample_color);
    REQUIRE(pf.size(1) == enc->pixel_channels());
    torch::nn::Linear layer(enc->pixel_channels(), 40);
    const auto uv = random_uv(n, V, S, S);
    const auto direct = layer(grid_sample_pixels(pf, uv));
    const auto readout = enc->make_readout(views, layer->weight, layer->bias);
    const auto flat = uv.reshape({-1, 2});
    const auto view = torch::arange(V).repeat({n});
    const auto fast = readout
                          .sample(views.geometry.stacked_level_taps(flat, view),
                                  views.geometry.image_taps(flat, view))
                          .view({n, V, -1});
    CHECK(max_abs(direct, fast) < 2e-5 * (1 + direct.abs().max().item<double>()));
    // p_v itself, and painting, without materialising the pixel feature.
    const auto p = enc->sample_pixel_features(views, views.geometry.stacked_level_taps(flat, view),
                                              views.geometry.image_taps(flat, view));
    CHECK(max_abs(p.view({n, V, -1}), grid_sample_pixels(pf, uv)) < 2e-5);
    const auto vis = torch::rand({V, n}) < 0.7;
    const auto uvv = uv.permute({1, 0, 2});
    const auto holder = torch::conv2d(pf, enc->reduction_layer->weight, enc->reduction_layer->bias);
    const auto painted =
        grid_sample_pixels(holder, uv).permute({1, 0, 2}) * vis.unsqueeze(-1).to(torch::kFloat);
    CHECK(max_abs(enc->paint(views, uvv, vis), painted) < 2e-5);
  }
}

TEST_CASE("the fused view-attention kernel equals bmm/softmax, values and gradients",
          "[model][shortcuts]") {
  torch::manual_seed(7);
  const int64_t n = 50, V = 3;
  auto q = torch::randn({n, V, 384}, torch::kDouble).requires_grad_(true);
  auto kv = torch::randn({n, V, 384}, torch::kDouble).requires_grad_(true);
  auto run = [&](bool fused) {
    const auto qq = q.narrow(2, 0, 128), k = kv.narrow(2, 0, 128), u = kv.narrow(2, 128, 256),
               r = q.narrow(2, 128, 256);
    return fused ? kernels::view_attention(q, kv, 128)
                 : torch::baddbmm(r, kernels::view_attention_weights(qq, k), u);
  };
  const auto g = torch::randn({n, V, 256}, torch::kDouble);
  const auto a = run(true), b = run(false);
  CHECK(max_abs(a, b) < 1e-12);
  const auto ga = torch::autograd::grad({a}, {q, kv}, {g});
  const auto gb = torch::autograd::grad({b}, {q, kv}, {g});
  CHECK(max_abs(ga[0], gb[0]) < 1e-12);
  CHECK(max_abs(ga[1], gb[1]) < 1e-12);
}

TEST_CASE("the view attention's clamp and bf16 operands: values and gradients",
          "[model][shortcuts]") {
  torch::manual_seed(8);
  const int64_t n = 40, V = 3;
  auto q = torch::randn({n, V, 384}, torch::kDouble).requires_grad_(true);
  auto kv = torch::randn({n, V, 384}, torch::kDouble).requires_grad_(true);
  const auto g = torch::randn({n, V, 256}, torch::kDouble);
  const auto a = kernels::view_attention(q, kv, 128, true);
  torch::Tensor b;
  {
    kernels::LibTorchForms forms;
    b = kernels::view_attention(q, kv, 128, true);
  }
  CHECK(max_abs(a, kernels::view_attention(q, kv, 128).relu()) < 1e-12);
  CHECK(max_abs(a, b) < 1e-12);
  CHECK((a == 0).any().item<bool>());
  const auto ga = torch::autograd::grad({a}, {q, kv}, {g});
  const auto gb = torch::autograd::grad({b}, {q, kv}, {g});
  CHECK(max_abs(ga[0], gb[0]) < 1e-12);
  CHECK(max_abs(ga[1], gb[1]) < 1e-12);
  // bf16 operands: the fp32 kernel on the same values, rounded once to bf16.
  const auto q16 = q.detach().to(torch::kBFloat16), kv16 = kv.detach().to(torch::kBFloat16);
  const auto out16 = kernels::view_attention(q16, kv16, 128, true);
  CHECK(out16.scalar_type() == torch::kBFloat16);
  const auto out32 =
      kernels::view_attention(q16.to(torch::kFloat), kv16.to(torch::kFloat), 128, true);
  CHECK(torch::equal(out16, out32.to(torch::kBFloat16)));
  // Its gradients: the fp32 kernel's, in bf16.
  const auto qb = q16.clone().requires_grad_(true), kb = kv16.clone().requires_grad_(true);
  const auto q32 = q16.to(torch::kFloat).requires_grad_(true),
             k32 = kv16.to(torch::kFloat).requires_grad_(true);
  const auto gh = g.to(torch::kBFloat16);
  const auto g16 =
      torch::autograd::grad({kernels::view_attention(qb, kb, 128, true)}, {qb, kb}, {gh});
  const auto g32 = torch::autograd::grad({kernels::view_attention(q32, k32, 128, true)}, {q32, k32},
                                         {gh.to(torch::kFloat)});
  CHECK(g16[0].scalar_type() == torch::kBFloat16);
  CHECK(torch::equal(g16[0], g32[0].to(torch::kBFloat16)));
  CHECK(torch::equal(g16[1], g32[1].to(torch::kBFloat16)));
}

TEST_CASE("the heads' view means equal LibTorch's mean, fp32 to the bit, with gradients",
          "[model][shortcuts]") {
  torch::manual_seed(9);
  const int64_t n = 30, V = 3, C = 16;
  const auto x = torch::randn({n, V, C}, torch::kDouble).requires_grad_(true);
  const auto d = torch::randn({n, C}, torch::kDouble).requires_grad_(true);
  const auto r = torch::randn({n, V, 2 * C}, torch::kDouble).requires_grad_(true);
  const auto g = torch::randn({n, C}, torch::kDouble);
  // The colour head's terms as the definition writes them.
  auto direct = [&](const torch::Tensor& xs, const torch::Tensor& ds, const torch::Tensor& rs) {
    auto c = xs + ds.unsqueeze(1);
    c = rs.defined() ? (c + rs.narrow(2, 0, C)).relu() + rs.narrow(2, C, C) : c.relu();
    return c.mean(1);
  };
  for (const bool readout : {true, false}) {
    INFO("readout " << readout);
    const auto rr = readout ? r : torch::Tensor();
    const auto a = kernels::colour_mean(x, d, rr);
    const auto b = direct(x, d, rr);
    CHECK(max_abs(a, b) < 1e-12);
    std::vector<torch::Tensor> inputs{x, d};
    if (readout) inputs.push_back(r);
    const auto ga = torch::autograd::grad({a}, inputs, {g});
    const auto gb = torch::autograd::grad({b}, inputs, {g});
    for (size_t i = 0; i < inputs.size(); ++i) CHECK(max_abs(ga[i], gb[i]) < 1e-12);
    // fp32: the same bits as LibTorch's operations in this order.
    const auto x32 = x.detach().to(torch::kFloat), d32 = d.detach().to(torch::kFloat);
    const auto r32 = readout ? r.detach().to(torch::kFloat) : torch::Tensor();
    CHECK(torch::equal(kernels::colour_mean(x32, d32, r32), direct(x32, d32, r32)));
    // bf16 terms are read as their fp32 values.
    const auto x16 = x32.to(torch::kBFloat16);
    CHECK(
        torch::equal(kernels::colour_mean(x16, d32, r32), direct(x16.to(torch::kFloat), d32, r32)));
  }
  const auto m = kernels::view_mean(x);
  CHECK(max_abs(m, x.mean(1)) < 1e-12);
  CHECK(max_abs(torch::autograd::grad({m}, {x}, {g})[0],
                torch::autograd::grad({x.mean(1)}, {x}, {g})[0]) < 1e-12);
  const auto x32 = x.detach().to(torch::kFloat);
  CHECK(torch::equal(kernels::view_mean(x32), x32.mean(1)));
  CHECK(torch::equal(kernels::view_mean(x32.to(torch::kBFloat16)),
                     x32.to(torch::kBFloat16).to(torch::kFloat).mean(1)));
}

TEST_CASE("the one-pass DPaRF query equals its LibTorch form", "[model][shortcuts]") {
  torch::manual_seed(8);
  const int64_t nt = 60, n = 500;
  TokenFrames frames{torch::randn({nt, 3}) * 0.3,
                     torch::eye(3).expand({nt, 3, 3}) + 0.2 * torch::randn({nt, 3, 3})};
  const auto xs = torch::randn({n, 3}) * 0.4;
  for (const Coordinate coordinate : {Coordinate::relative, Coordinate::none}) {
    for (int nk : {1, 4, 7}) {
      const bool local = coordinate == Coordinate::relative;
      const kernels::FieldQueryOptions options{nk, 0.5, local, 10, true};
      auto a = kernels::nearest_fields(xs, frames.origins, frames.rotations, options);
      auto b = [&] {
        kernels::LibTorchForms libtorch_forms;
        return kernels::nearest_fields(xs, frames.origins, frames.rotations, options);
      }();
      INFO(config::name_of(coordinate) << " nk " << nk);
      CHECK(torch::equal(a.index, b.index));
      CHECK(max_abs(a.weight, b.weight) < 1e-6);
      CHECK(a.local.defined() == local);
      CHECK(b.local.defined() == local);
      if (local) {
        CHECK(max_abs(a.local, b.local) < 1e-6);
        CHECK(max_abs(kernels::weighted_codes(a), kernels::weighted_codes(b)) < 1e-5);
      }
    }
  }
}

TEST_CASE("the DPaRF query picks the nearest fields, ties by index, NaN never nearer",
          "[model][shortcuts]") {
  // Origins on a coarse lattice, each position three times at indices far apart (other blocks
  // of the selection's scan), points on and between lattice positions: many exact ties.
  torch::manual_seed(10);
  const auto lattice = torch::randint(0, 3, {25, 3}).to(torch::kFloat) * 0.25;
  const auto origins = torch::cat({lattice, lattice.flip(0), lattice});  // 75 origins
  const int64_t nt = origins.size(0);
  auto xs = torch::cat({lattice.index_select(0, torch::randint(0, 25, {100})),
                        torch::randint(0, 5, {100, 3}).to(torch::kFloat) * 0.125});
  xs[7][1] = std::nanf("");  // a point with NaN distances
  const auto rotations = torch::eye(3).expand({nt, 3, 3});
  const float* o = origins.data_ptr<float>();
  for (int64_t nk : {1, 4, 9}) {
    const auto q = kernels::nearest_fields(xs, origins, rotations, {nk, 0.5, false, 10, true});
    // Expected: a stable sort of the exact squared distances, NaN last.
    auto expected = torch::empty({xs.size(0), nk}, torch::kLong);
    for (int64_t n = 0; n < xs.size(0); ++n) {
      std::vector<std::pair<float, int64_t>> d;
      for (int64_t t = 0; t < nt; ++t) {
        const float dx = xs[n][0].item<float>() - o[3 * t],
                    dy = xs[n][1].item<float>() - o[3 * t + 1],
                    dz = xs[n][2].item<float>() - o[3 * t + 2];
        d.emplace_back(dx * dx + dy * dy + dz * dz, t);
      }
      std::stable_sort(d.begin(), d.end(), [](const auto& a, const auto& b) {
        return std::isnan(b.first) ? !std::isnan(a.first) : a.first < b.first;
      });
      for (int64_t k = 0; k < nk; ++k) expected[n][k] = d[k].second;
    }
    INFO("nk " << nk);
    CHECK(torch::equal(q.index, expected));
  }
}

TEST_CASE("the DPaRF query's encoding arguments round as the method says, on every CPU",
          "[model][shortcuts]") {
  // The arguments l f + phase of the local coordinates' encoding: one rounding (fma) when fused,
  // else the product rounded and then the phase added; the same bits whatever vector clone runs.
  torch::manual_seed(9);
  const int64_t nt = 40, n = 300, nk = 5, nf = 10;
  TokenFrames frames{torch::randn({nt, 3}) * 0.3,
                     torch::eye(3).expand({nt, 3, 3}) + 0.2 * torch::randn({nt, 3, 3})};
  const auto xs = torch::randn({n, 3}) * 0.4;
  const auto freqs = kernels::pe_frequencies(nf, xs.options()).contiguous();
  const auto phases = kernels::pe_phases(nf, xs.options()).contiguous();
  for (const bool fused : {true, false}) {
    const auto q =
        kernels::nearest_fields(xs, frames.origins, frames.rotations, {nk, 0.5, true, nf, fused});
    const auto l = q.local.contiguous();
    auto expected = torch::empty_like(q.args);
    const float* lp = l.data_ptr<float>();
    const float* fp = freqs.data_ptr<float>();
    const float* pp = phases.data_ptr<float>();
    float* e = expected.data_ptr<float>();
    for (int64_t m = 0; m < n * nk; ++m)
      for (int64_t j = 0; j < 2 * nf; ++j)
        for (int i = 0; i < 3; ++i) {
          const float x = lp[m * 3 + i];
          volatile float product = x * fp[j];  // rounded on its own
          e[(m * 2 * nf + j) * 3 + i] = fused ? std::fma(x, fp[j], pp[j]) : product + pp[j];
        }
    INFO("fused " << fused);
    CHECK(torch::equal(q.args, expected));
  }
}

TEST_CASE("readout windows sample a full-resolution map as grid_sample does",
          "[model][sampling][windows]") {
  torch::manual_seed(11);
  const int64_t V = 3, C = 6, H = 23, W = 31, n = 400;
  const auto map = torch::randn({V, C, H, W}, torch::kDouble);
  PixelWindows win;
  // An interior rectangle, one touching the right and bottom borders, the whole image.
  const std::vector<std::array<int64_t, 4>> rects{{4, 3, 12, 9}, {20, 10, 11, 13}, {0, 0, W, H}};
  std::vector<torch::Tensor> rows;
  int64_t offset = 0;
  for (int64_t v = 0; v < V; ++v) {
    const auto [x0, y0, w, h] = rects[v];
    win.x0.push_back(x0), win.y0.push_back(y0), win.w.push_back(w), win.h.push_back(h),
        win.offset.push_back(offset);
    offset += w * h;
    rows.push_back(
        map[v].slice(1, y0, y0 + h).slice(2, x0, x0 + w).permute({1, 2, 0}).reshape({-1, C}));
  }
  const auto table = torch::cat(rows);
  REQUIRE(win.rows() == table.size(0));
  // The window pixels, in table order, are where the table's rows come from.
  const auto [px, pv] = win.pixels(torch::TensorOptions().dtype(torch::kDouble));
  const auto at =
      map.permute({0, 2, 3, 1})
          .index({pv, px.select(1, 1).to(torch::kLong), px.select(1, 0).to(torch::kLong)});
  CHECK(torch::equal(at, table));

  const auto uv = random_uv(n, V, W, H).to(torch::kDouble);
  const auto flat = uv.reshape({-1, 2});
  const auto view = torch::arange(V).repeat({n});
  const auto [taps, inside] = win.taps(flat, view, H, W);
  const auto direct = grid_sample_pixels(map, uv).reshape({-1, C});
  const auto fast = kernels::weighted_gather(table, taps);
  // Inside: grid_sample's value; outside: flagged, with zero weights.
  const auto x = flat.select(1, 0).clamp(0, W - 1), y = flat.select(1, 1).clamp(0, H - 1);
  const auto ix0 = x.floor().clamp(0, W - 2), iy0 = y.floor().clamp(0, H - 2);
  const auto ix1 = (ix0 + 1).clamp_max(W - 1), iy1 = (iy0 + 1).clamp_max(H - 1);
  auto expected = torch::zeros_like(inside);
  for (int64_t m = 0; m < flat.size(0); ++m) {
    const auto [x0, y0, w, h] = rects[view[m].item<int64_t>()];
    expected[m] = ix0[m].item<double>() >= x0 && ix1[m].item<double>() < x0 + w &&
                  iy0[m].item<double>() >= y0 && iy1[m].item<double>() < y0 + h;
  }
  CHECK(torch::equal(inside, expected));
  CHECK(inside.sum().item<int64_t>() > n / 2);
  CHECK((~inside).sum().item<int64_t>() > 20);
  CHECK(max_abs(fast.index({inside}), direct.index({inside})) < 1e-12);
  CHECK(fast.index({~inside}).abs().max().item<double>() == 0);
  CHECK(taps.weight.index({~inside}).abs().max().item<double>() == 0);
}

TEST_CASE("a readout table computed only where the windows read gives the same window values",
          "[model][sampling][windows]") {
  torch::manual_seed(12);
  torch::NoGradGuard no_grad;
  Encoder encoder(EncoderConfig{}, true, 32);
  const int64_t V = 3, H = 48, W = 56;
  const auto enc = encoder->forward(torch::rand({V, 3, H, W}));
  const auto weight = 0.1 * torch::randn({16, encoder->pixel_channels()});
  const auto bias = torch::randn({16});
  PixelWindows win;
  // An interior rectangle, one touching the right and bottom borders, the whole image.
  const std::vector<std::array<int64_t, 4>> rects{{5, 7, 13, 9}, {40, 30, 16, 18}, {0, 0, W, H}};
  int64_t offset = 0;
  for (const auto& [x0, y0, w, h] : rects) {
    win.x0.push_back(x0), win.y0.push_back(y0), win.w.push_back(w), win.h.push_back(h),
        win.offset.push_back(offset);
    offset += w * h;
  }
  const auto [uv, view] = win.pixels(torch::TensorOptions().dtype(torch::kFloat));
  const auto footprint = win.footprint(enc.geometry, uv.options());
  const auto level_taps = enc.geometry.stacked_level_taps(uv, view);
  const auto image_taps = enc.geometry.image_taps(uv, view);
  // Every tap of every window pixel lies in its level's rectangle.
  const auto idx = level_taps.index.contiguous();
  int64_t level_offset = 0, outside = 0, column = 0;
  for (size_t l = 0; l < enc.geometry.level_sizes.size(); ++l) {
    const auto [h, w] = enc.geometry.level_sizes[l];
    const int64_t taps = (h == H && w == W) ? 4 : 9;
    const auto r = idx.slice(1, column, column + taps) - level_offset - view.unsqueeze(1) * h * w;
    const auto y = r.div(w, "floor"), x = r.remainder(w);
    for (int64_t v = 0; v < V; ++v) {
      const auto& t = footprint[l][v];
      const auto mine = (view == v).unsqueeze(1).expand_as(x);
      outside +=
          (mine & ((x < t.x0) | (x >= t.x1) | (y < t.y0) | (y >= t.y1))).sum().item<int64_t>();
    }
    // the whole image's window needs its whole map; the small one far less
    CHECK(footprint[l][2].x0 == 0);
    CHECK(footprint[l][2].x1 == w);
    CHECK((footprint[l][0].x1 - footprint[l][0].x0) * (footprint[l][0].y1 - footprint[l][0].y0) <
          h * w / 2);
    level_offset += V * h * w;
    column += taps;
  }
  CHECK(outside == 0);
  // The window values from the partial table are those of the whole one.
  const auto whole = encoder->make_readout(enc, weight, bias);
  auto part = encoder->make_readout(enc, weight, bias, &footprint);
  CHECK(part.table.sizes() == whole.table.sizes());
  // (Products of fewer rows may sum in another order: equal up to float rounding.)
  const auto a = part.sample(level_taps, image_taps), b = whole.sample(level_taps, image_taps);
  CHECK(max_abs(a, b) <= 1e-6 * std::max(1.0, b.abs().max().item<double>()));
}

TEST_CASE("body windows contain the projection of every point within the culling distance",
          "[model][windows]") {
  const auto frame = test::synthetic_frame(300, 24, 3, 64);
  const auto& in = frame.inputs;
  FrameGeometry geo;
  geo.K = in.K.to(torch::kFloat), geo.R = in.R.to(torch::kFloat),
  geo.T = in.T.to(torch::kFloat).reshape({-1, 3, 1});
  PixelGeometry g;
  g.views = 3, g.height = 64, g.width = 64;
  for (double r : {0.1, 0.02}) {
    const auto win = body_windows(geo, in.vertices, r, g);
    REQUIRE(win.offset.size() == 3);
    int64_t area = 0;
    for (int64_t v = 0; v < 3; ++v) area += win.w[v] * win.h[v];
    CHECK(area < 3 * 64 * 64);  // a real crop, not the whole images
    // Points in the balls of radius r (on their surfaces too) around the vertices.
    torch::manual_seed(12);
    const int64_t n = 20000;
    auto dir = torch::randn({n, 3});
    dir = dir / dir.norm(2, 1, true);
    const auto radius =
        r * torch::where(torch::rand({n}) < 0.3, torch::ones({n}), torch::rand({n}).pow(1.0 / 3));
    const auto pts = in.vertices.index_select(0, torch::randint(0, in.vertices.size(0), {n})) +
                     dir * radius.unsqueeze(1);
    const auto uv =
        geometry::project_views(pts, geo.K, geo.R, geo.T).permute({1, 0, 2}).reshape({-1, 2});
    const auto view = torch::arange(3).repeat({n});
    CHECK(win.taps(uv, view, 64, 64).second.all().item<bool>());
    // The vertices themselves lie inside (left edges checked here).
    const auto vu = geometry::project_views(in.vertices, geo.K, geo.R, geo.T);
    for (int64_t v = 0; v < 3; ++v)
      CHECK(win.x0[v] <=
            std::max<int64_t>(0, int64_t(std::floor(vu[v].select(1, 0).min().item<double>()))));
  }
}

TEST_CASE("readout windows give the level tables' values, inside and outside the windows",
          "[model][windows]") {
  const auto frame = test::synthetic_frame(300, 24, 3, 48);
  auto c = test::tiny_model_config();
  torch::manual_seed(13);
  TransHuman model(c);
  model->eval();
  torch::NoGradGuard ng;
  // With a culling distance inference on CPU makes windows; without one, the level tables.
  const auto a = model->prepare(frame.inputs, 0.1), b = model->prepare(frame.inputs, 0);
  REQUIRE(std::holds_alternative<WindowReadouts>(a.pixels));
  REQUIRE(std::holds_alternative<PixelReadouts>(b.pixels));
  torch::manual_seed(14);
  const int64_t n = 500;
  // Near the body (inside the windows) and far from it (read from the levels).
  const auto near = frame.inputs.vertices.index_select(0, torch::randint(0, 300, {n})) +
                    0.05 * torch::rand({n, 3});
  const auto far = frame.inputs.vertices.index_select(0, torch::randint(0, 300, {n})) +
                   0.6 * torch::randn({n, 3});
  const auto pts = torch::cat({near, far}), dirs = torch::randn({2 * n, 3});
  const auto& in = frame.inputs;
  const auto uv = geometry::project_views(far, in.K.to(torch::kFloat), in.R.to(torch::kFloat),
                                          in.T.to(torch::kFloat).reshape({-1, 3, 1}))
                      .permute({1, 0, 2})
                      .reshape({-1, 2});
  const auto view = torch::arange(3).repeat({n});
  CHECK((~std::get<WindowReadouts>(a.pixels).windows.taps(uv, view, 48, 48).second)
            .sum()
            .item<int64_t>() > 100);
  const auto ya = model->forward(a, pts, dirs), yb = model->forward(b, pts, dirs);
  INFO("max |raw| " << yb.abs().max().item<double>());
  CHECK(max_abs(ya, yb) < 1e-5 * (1 + yb.abs().max().item<double>()));
  CHECK(std::get<WindowReadouts>(a.pixels).alpha.table.scalar_type() == torch::kFloat);
  {  // Under bf16 the window tables are stored in bf16 (their gathers sum in fp32): the outputs
     // differ from the level tables' by that rounding only.
    Products bf16;
    bf16.precision = Precision::bf16;
    model->set_products(bf16);
    const auto c = model->prepare(frame.inputs, 0.1), d = model->prepare(frame.inputs, 0);
    const auto& windows = std::get<WindowReadouts>(c.pixels);
    CHECK(windows.alpha.table.scalar_type() == torch::kBFloat16);
    CHECK(windows.color.table.scalar_type() == torch::kBFloat16);
    const auto yc = model->forward(c, pts, dirs), yd = model->forward(d, pts, dirs);
    const double scale = 1 + yd.abs().max().item<double>();
    INFO("bf16: max |raw| " << scale - 1 << ", windows against levels " << max_abs(yc, yd));
    CHECK(max_abs(yc, yd) < 1e-2 * scale);
    CHECK(max_abs(yc, yd) > 1e-5 * scale);  // the tables' rounding shows
    model->set_products(Products{});
  }
  // Under autograd (training) the level tables stay.
  torch::AutoGradMode grad(true);
  CHECK(std::holds_alternative<PixelReadouts>(model->prepare(frame.inputs, 0.1).pixels));
}
