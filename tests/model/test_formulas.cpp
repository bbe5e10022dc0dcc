// Formulas of METHOD 3 and 4 against independent values from tests/python/model_reference.py
// (numpy, torchvision, and the reference code's torch idioms).
#include <torch/torch.h>

#include <catch2/catch.hpp>

#include "model/encoder.hpp"
#include "model/fdi.hpp"
#include "model/frame_fixture.hpp"
#include "model/kernels/encoding.hpp"
#include "model/kernels/nearest_fields.hpp"
#include "model/kernels/view_attention.hpp"
#include "model/transhe.hpp"
#include "model/transhuman.hpp"
#include "render/volume.hpp"

using namespace th;
using namespace th::model;

using test::max_abs;

TEST_CASE("positional encodings: layout and float32 values match numpy", "[model][formulas]") {
  torch::manual_seed(0);
  const auto x = torch::rand({300, 3}) * 2 - 1;  // token positions lie in [-1, 1]
  auto d = torch::randn({50, 3});
  d = d / d.norm(2, 1, true);
  test::PythonReference py("formulas_pe");
  py.add("x", x);
  py.add("d", d);
  const auto ref = py.run("pe");
  // The 32-frequency token PE: arguments up to 2^31 pi make it pseudo-random, yet value by value
  // equal to numpy's separately rounded float32 evaluation (up to sin's last-bit rounding).
  const auto pe32 = kernels::sincos_encoding(x, 32, false);
  REQUIRE(pe32.sizes() == ref.at("pe32").sizes());
  CHECK(max_abs(pe32, ref.at("pe32")) < 1e-6);
  CHECK(max_abs(kernels::sincos_encoding(x, 10, true), ref.at("pe10")) < 1e-6);
  CHECK(max_abs(kernels::direction_encoding(d), ref.at("gamma")) < 1e-6);
  // The fused variant reproduces torch.addcmul (FMA) exactly as the reference evaluates it, which
  // differs from the separately rounded values at high frequencies.
  CHECK(max_abs(kernels::sincos_encoding(x, 32, false, true), ref.at("pe32_addcmul")) < 1e-6);
  CHECK(max_abs(ref.at("pe32"), ref.at("pe32_addcmul")) > 0.1);
  // Low frequencies are the same either way: layout check [sin x, sin y, sin z, cos x, ...].
  CHECK(pe32[0][0].item<double>() == Approx(std::sin(M_PI * x[0][0].item<double>())).margin(1e-6));
  CHECK(pe32[0][4].item<double>() == Approx(std::cos(M_PI * x[0][1].item<double>())).margin(1e-6));
  CHECK(pe32[0][8].item<double>() ==
        Approx(std::sin(2 * M_PI * x[0][2].item<double>())).margin(1e-6));
}

TEST_CASE("DPaRF: nearest fields, distance softmax, local coordinates and h_v",
          "[model][formulas]") {
  torch::manual_seed(1);
  const int64_t nt = 40, n = 200, V = 3, C = 16;
  TokenFrames frames{torch::randn({nt, 3}) * 0.3,
                     torch::eye(3).expand({nt, 3, 3}) + 0.2 * torch::randn({nt, 3, 3})};
  const auto tokens = torch::randn({V, nt, C});
  const auto xs = torch::randn({n, 3}) * 0.3;
  DPaRFConfig cfg;
  cfg.nk = 7;
  test::PythonReference py("formulas_dparf");
  py.add("xs", xs);
  py.add("origins", frames.origins);
  py.add("rotations", frames.rotations);
  py.add("tokens", tokens);
  py.add("nk", torch::tensor({7.0f}));
  py.add("temperature", torch::tensor({0.5f}));
  const auto ref = py.run("dparf");
  auto q = kernels::nearest_fields(xs, frames.origins, frames.rotations,
                                   {7, 0.5, /*local=*/true, cfg.pe_freqs, true});
  CHECK(torch::equal(q.index, ref.at("index")));
  CHECK(max_abs(q.weight, ref.at("weights")) < 1e-6);
  CHECK(max_abs(q.local, ref.at("local")) < 1e-5);
  const auto coords = kernels::weighted_codes(q);
  // h_v = sum_k w_k [T_v(k); g_k]: the tokens weighted here, sum_k w_k g_k from the query.
  // 1-ulp differences of l (float32) are amplified by f_9 = 512 pi in the encoding.
  const auto T_k = tokens.index_select(1, q.index.flatten()).view({V, n, cfg.nk, C});
  const auto h_tokens = (q.weight.view({1, n, cfg.nk, 1}) * T_k).sum(2).permute({1, 0, 2});
  const auto h = torch::cat({h_tokens, coords.unsqueeze(1).expand({n, V, -1})}, 2);
  CHECK(max_abs(h, ref.at("h")) < 1e-4);
}

TEST_CASE("FDI: attention over the key views, as the reference's bmm/softmax(dim=1)",
          "[model][formulas]") {
  torch::manual_seed(2);
  TransHuman model{ModelConfig{}};  // the paper's fusion
  auto& fdi = model->fdi;
  const int64_t n = 64, V = 3;
  const auto s = torch::relu(torch::randn({n, V, 256})), a = torch::relu(torch::randn({n, V, 256}));
  test::PythonReference py("formulas_fdi");
  py.add("s", s);
  py.add("a", a);
  for (auto [name, layer] : {std::pair{"key0", fdi->key0},
                             {"value0", fdi->value0},
                             {"key1", fdi->key1},
                             {"value1", fdi->value1},
                             {"fc_1", fdi->fc_1},
                             {"fc_2", fdi->fc_2}}) {
    py.add(std::string(name) + "_w", layer->weight);
    py.add(std::string(name) + "_b", layer->bias);
  }
  const auto ref = py.run("fdi");
  torch::NoGradGuard ng;
  // [n, query view, key view]
  const auto att = kernels::view_attention_weights(fdi->key1(s), fdi->key0(a));
  CHECK(max_abs(att, ref.at("attention")) < 1e-6);
  CHECK(torch::allclose(att.sum(2), torch::ones({n, V})));  // normalised over the key views
  CHECK(max_abs(fdi->forward(fdi->fold(), s, a, Products{}), ref.at("e")) < 1e-4);
}

TEST_CASE("compositing: 1e10 last interval, 1e-10 transmittance term, black background",
          "[render][formulas]") {
  torch::manual_seed(3);
  const int64_t R = 20, S = 16;
  auto raw = torch::randn({R, S, 4}) * 3;
  // Ray 0: an opaque sample (alpha = 1) early: later weights come only from the 1e-10 term.
  raw.index_put_({0, 3, 3}, 1e4);
  // Ray 1: empty except the last sample, whose 1e10 interval makes it opaque.
  raw.index_put_({1, torch::indexing::Slice(), 3}, -1.0);
  raw.index_put_({1, S - 1, 3}, 0.01);
  // Ray 2: all empty: black, acc 0.
  raw.index_put_({2, torch::indexing::Slice(), 3}, -1.0);
  const auto z = std::get<0>(torch::sort(torch::rand({R, S}) * 2 + 1, 1));
  const auto d = torch::randn({R, 3});
  test::PythonReference py("formulas_composite");
  py.add("raw", raw);
  py.add("z", z);
  py.add("d", d);
  const auto ref = py.run("composite");
  const auto c = render::composite(raw, z, d);
  CHECK(max_abs(c.rgb, ref.at("rgb")) < 1e-6);
  CHECK(max_abs(c.depth, ref.at("depth")) < 1e-5);
  CHECK(max_abs(c.acc, ref.at("acc")) < 1e-6);
  CHECK(max_abs(c.weights, ref.at("weights")) < 1e-6);
  const auto after = c.weights[0].narrow(0, 4, S - 4);
  const auto after_ref = ref.at("weights")[0].narrow(0, 4, S - 4);
  CHECK(after.max().item<double>() > 0);  // the 1e-10 term keeps them non-zero ...
  CHECK(after.max().item<double>() < 1e-9);
  CHECK(torch::allclose(after, after_ref, 1e-3, 0));  // ... and equal to the reference's
  CHECK(c.acc[1].item<double>() == Approx(1.0).margin(1e-6));
  CHECK(c.rgb[2].abs().max().item<double>() == 0);
  CHECK(c.acc[2].item<double>() == 0);
}

TEST_CASE("encoder: ResNet-18 trunk, pixel feature and reduction equal torchvision's",
          "[model][formulas]") {
  torch::manual_seed(4);
  EncoderConfig cfg;
  Encoder enc(cfg, true, 192);
  enc->eval();  // batch statistics at inference [parity]
  const auto images = torch::rand({3, 3, 32, 40});
  test::PythonReference py("formulas_encoder");
  py.add("images", images);
  for (const auto& p : enc->named_parameters()) py.add(p.key(), p.value());
  for (const auto& b : enc->named_buffers())
    if (b.key().find("num_batches") == std::string::npos) py.add(b.key(), b.value());
  const auto ref = py.run("encoder");
  torch::NoGradGuard ng;
  const auto out = enc->forward(images);
  CHECK(max_abs(out.levels[0], ref.at("l0")) < 1e-4);
  CHECK(max_abs(out.levels[1], ref.at("l1")) < 1e-4);
  CHECK(max_abs(out.levels[2], ref.at("l2")) < 1e-4);
  const auto pixel = test::pixel_feature_map(out.levels, images, enc->upsample_color);
  CHECK(max_abs(pixel, ref.at("pixel")) < 1e-4);
  CHECK(max_abs(torch::conv2d(pixel, enc->reduction_layer->weight, enc->reduction_layer->bias),
                ref.at("holder")) < 1e-4);
}

TEST_CASE("TransHE: ViT-Tiny blocks and positional encoding as timm computes them",
          "[model][formulas]") {
  torch::manual_seed(5);
  TransHEConfig cfg;
  cfg.depth = 2;
  TransHE vit(cfg);
  const auto tokens = torch::randn({3, 30, 192});
  const auto positions = torch::rand({30, 3}) * 2 - 1;
  test::PythonReference py("formulas_vit");
  py.add("tokens", tokens);
  py.add("positions", positions);
  py.add("depth", torch::tensor({2.0f}));
  py.add("heads", torch::tensor({3.0f}));
  for (const auto& p : vit->named_parameters()) py.add(p.key(), p.value());
  const auto ref = py.run("vit");
  torch::NoGradGuard ng;
  CHECK(max_abs(vit->forward(tokens, positions), ref.at("out")) < 1e-4);
}

TEST_CASE("token grouping: cluster means include invisible (zero) vertices by default",
          "[model][formulas]") {
  const auto values = torch::tensor({1.0f, 2.0f, 0.0f, 4.0f}).view({1, 4, 1});
  const auto labels = torch::tensor({0, 0, 1, 1}, torch::kLong);
  const auto vis = torch::tensor({true, true, false, true}).view({1, 4});
  CHECK(torch::allclose(cluster_mean(values, labels, 3).flatten(),
                        torch::tensor({1.5f, 2.0f, 0.0f})));
  CHECK(torch::allclose(cluster_mean(values, labels, 3, vis).flatten(),
                        torch::tensor({1.5f, 4.0f, 0.0f})));
  // Token positions: ((p + 1.5) / 3 - 0.5) * 2 in float64, rounded once.
  const auto p = torch::tensor({0.3, -1.2, 0.7}, torch::kDouble).view({1, 3});
  const auto n = normalize_token_positions(p, 1.5, torch::zeros({1}));
  CHECK(n.scalar_type() == torch::kFloat);
  CHECK(n[0][0].item<float>() == static_cast<float>(((0.3 + 1.5) / 3 - 0.5) * 2));
}
