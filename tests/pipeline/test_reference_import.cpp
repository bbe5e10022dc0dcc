// Importing checkpoints of the reference implementation (METHOD 8) written by Debian's
// python3-torch, pretrained encoder weights, and our own weights.
#include <torch/torch.h>

#include <catch2/catch.hpp>
#include <fstream>

#include "body/grouping.hpp"
#include "core/error.hpp"
#include "io/npy.hpp"
#include "model/encoder.hpp"
#include "model/frame_fixture.hpp"
#include "model/transhuman.hpp"
#include "pipeline/checkpoint.hpp"
#include "pipeline/pipeline.hpp"
#include "pipeline/reference_import.hpp"

using namespace th;
using namespace th::model;
using namespace th::pipeline;

namespace {

std::map<std::string, torch::Tensor> expected_tensors(const std::filesystem::path& dir) {
  std::map<std::string, torch::Tensor> out;
  std::ifstream m((dir / "manifest.txt").string());
  std::string line;
  while (std::getline(m, line)) {
    std::istringstream in(line);
    std::string name, dt;
    in >> name >> dt;
    std::vector<int64_t> shape;
    for (int64_t s; in >> s;) shape.push_back(s);
    out[name] = test::read_raw((dir / (name + ".bin")).string(), shape,
                               dt == "f32" ? torch::kFloat : torch::kLong);
  }
  return out;
}

const std::filesystem::path& fixtures() {
  static const auto dir = [] {
    auto d = test::scratch_dir("checkpoint_import");
    REQUIRE(test::run_python("tests/python/model_checkpoint.py", d.string()) == 0);
    return d;
  }();
  return dir;
}

}  // namespace

TEST_CASE("a reference .pth imports with equal tensors", "[pipeline][checkpoint]") {
  const auto& dir = fixtures();
  const auto expected = expected_tensors(dir);
  for (const char* file : {"full.pth", "bare.pth"}) {
    INFO(file);
    TransHuman model(ModelConfig{});
    const auto report = import_reference_checkpoint(*model, dir / file);
    CHECK(report.loaded.size() == model->named_parameters().size() + model->named_buffers().size());
    // Unused entries are ignored: ResNet layer3/4 and fc, cls/mask tokens, PE buffers, xyzc_net.
    const std::set<std::string> ignored(report.ignored.begin(), report.ignored.end());
    CHECK(ignored.count("ViT.cls_token"));
    CHECK(ignored.count("xyzc_net.conv0.subm0.weight"));
    CHECK(ignored.count("encoder.model.layer4.1.bn2.running_var"));
    int compared = 0;
    for (const auto& p : model->named_parameters()) {
      const auto ref = reference_name(p.key());
      REQUIRE(expected.count(ref));
      const auto e = expected.at(ref).reshape(p.value().sizes());
      INFO(p.key() << " <- " << ref);
      CHECK(torch::equal(p.value(), e));
      ++compared;
    }
    for (const auto& b : model->named_buffers()) {
      const auto ref = reference_name(b.key());
      INFO(b.key() << " <- " << ref);
      CHECK(torch::equal(b.value(),
                         expected.at(ref).reshape(b.value().sizes()).to(b.value().dtype())));
    }
    CHECK(compared == static_cast<int>(model->named_parameters().size()));
  }
  // The name map of METHOD 8.
  CHECK(reference_name("fdi.key0.weight") == "spatial_key_value_0.key_embed.weight");
  CHECK(reference_name("fdi.value1.bias") == "spatial_key_value_1.value_embed.bias");
  CHECK(reference_name("human.ViT.blocks.3.attn.qkv.weight") == "ViT.blocks.3.attn.qkv.weight");
  CHECK(reference_name("heads.rgb_res_1.weight") == "rgb_res_1.weight");
  CHECK(reference_name("encoder.model.layer2.0.downsample.1.running_mean") ==
        "encoder.model.layer2.0.downsample.1.running_mean");
}

TEST_CASE("a mis-shaped or missing tensor fails naming the key", "[pipeline][checkpoint]") {
  const auto& dir = fixtures();
  TransHuman model(ModelConfig{});
  const auto before = model->heads->fc_3->weight.clone();
  CHECK_THROWS_AS(import_reference_checkpoint(*model, dir / "wrong_shape.pth"), Error);
  CHECK_THROWS_WITH(import_reference_checkpoint(*model, dir / "wrong_shape.pth"),
                    Catch::Contains("fc_3.weight") && Catch::Contains("[256, 255, 1]"));
  CHECK(torch::equal(before, model->heads->fc_3->weight));  // nothing copied
  CHECK_THROWS_WITH(import_reference_checkpoint(*model, dir / "missing.pth"),
                    Catch::Contains("alpha_fc.bias"));
  // A key the reference network does not have, and integer or boolean values where weights go.
  CHECK_THROWS_WITH(
      import_reference_checkpoint(*model, dir / "extra_key.pth"),
      Catch::Contains("extra_key.pth: key 'fc_5.weight' is not part of the TransHuman reference"));
  CHECK_THROWS_WITH(
      import_reference_checkpoint(*model, dir / "int_tensor.pth"),
      Catch::Contains("key 'alpha_fc.bias' holds Long values, the model expects Float"));
  CHECK_THROWS_WITH(import_reference_checkpoint(*model, dir / "bool_tensor.pth"),
                    Catch::Contains("key 'rgb_fc.bias' holds Bool values"));
  CHECK(torch::equal(before, model->heads->fc_3->weight));
  CHECK_THROWS_WITH(import_reference_checkpoint(*model, dir / "nonexistent.pth"),
                    Catch::Contains("does not exist"));
  const auto junk = dir / "junk.pth";
  std::ofstream(junk.string()) << "not a zip file";
  CHECK_THROWS_AS(import_reference_checkpoint(*model, junk), Error);
  // An ablation with other shapes is refused the same way.
  ModelConfig wo_rgb;
  wo_rgb.fdi.raw_rgb = false;
  TransHuman other(wo_rgb);
  CHECK_THROWS_WITH(import_reference_checkpoint(*other, dir / "full.pth"),
                    Catch::Contains("full.pth: key '") && Catch::Contains("' has shape [") &&
                        Catch::Contains("], the model expects ["));
}

TEST_CASE("a reference .pth is loaded only with its token groups, or on an explicit 'compute'",
          "[pipeline][checkpoint][tokens]") {
  const auto& dir = fixtures();
  const auto groups = test::scratch_dir("checkpoint_import_groups");
  REQUIRE(test::run_python("tests/python/kmeans_reference.py", groups.string() + " 690 300") == 0);
  auto load = [&](const std::string& kmeans_file) {
    ModelConfig c;
    c.grouping.kmeans_file = kmeans_file;
    c.grouping.cache_dir = (groups / "cache").string();
    TransHuman model(c);
    load_weights(*model, dir / "full.pth");
    return model;
  };
  // No groups named: refused, naming the key and the reference's file.
  try {
    load("");
    FAIL("a .pth without model.grouping.kmeans_file was loaded");
  } catch (const Error& e) {
    const std::string message = e.what();
    CHECK_THAT(message, Catch::Contains((dir / "full.pth").string()) &&
                            Catch::Contains("model.grouping.kmeans_file") &&
                            Catch::Contains("kmeans_dict/kmeans_dict_300.npy") &&
                            Catch::Contains("'compute'"));
  }
  // The reference's file: its labels, as the reference reads them.
  const auto with_file = load((groups / "kmeans_dict.npy").string());
  CHECK(torch::equal(with_file->token_groups().labels,
                     body::load_reference_kmeans(groups / "kmeans_dict.npy", 690)));
  // The explicit opt-in: no groups yet, computed from model.grouping when a frame is first
  // prepared.
  auto computed = load("compute");
  CHECK(computed->token_groups().empty());
  Tokens tokens(*computed, torch::rand({690, 3}, torch::kFloat64));
  CHECK(computed->token_groups().origin == "canonical_kmeans num_tokens=300 seed=0");
}

TEST_CASE("the full checkpoint's other entries are readable", "[pipeline][checkpoint]") {
  const auto all = read_torch_state_dict(fixtures() / "full.pth", "");
  CHECK(all.count("net.fc_0.weight"));
  CHECK(all.at("epoch").item<int64_t>() == 2100);
  CHECK(all.at("recorder.step").item<int64_t>() == 1234);
}

TEST_CASE("scripts/export_pretrained.py output loads into the encoder", "[pipeline][checkpoint]") {
  const auto& dir = fixtures();
  REQUIRE(test::run_python("scripts/export_pretrained.py",
                           "--weights " + (dir / "resnet18.pth").string() + " --out " +
                               (dir / "resnet18.npz").string()) == 0);
  auto cfg = test::tiny_model_config();
  cfg.encoder.pretrained = (dir / "resnet18.npz").string();
  TransHuman model(cfg);  // loads in the constructor
  const auto expected = expected_tensors(dir);
  for (const auto& p : model->encoder->model->named_parameters()) {
    INFO(p.key());
    CHECK(torch::equal(p.value(), expected.at("encoder.model." + p.key())));
  }
  for (const auto& b : model->encoder->model->named_buffers()) {
    INFO(b.key());
    CHECK(torch::equal(b.value(), expected.at("encoder.model." + b.key()).to(b.value().dtype())));
  }
}

TEST_CASE("pretrained ResNet-18 weights load from an npz, own weights round-trip",
          "[pipeline][checkpoint]") {
  const auto dir = test::scratch_dir("checkpoint_own");
  TransHuman a(test::tiny_model_config()), b(test::tiny_model_config());
  a->set_token_groups({torch::tensor({0, 1, 1, 0}), "test groups"});
  save_model_weights(*a, dir / "model.pt");
  load_model_weights(*b, dir / "model.pt");
  CHECK(torch::equal(b->token_groups().labels, a->token_groups().labels));
  for (const auto& p : a->named_parameters())
    CHECK(torch::equal(p.value(), b->named_parameters()[p.key()]));
  // An npz with torchvision names (what scripts/export_pretrained.py writes).
  std::map<std::string, torch::Tensor> resnet;
  for (const auto& p : a->encoder->model->named_parameters())
    resnet[p.key()] = torch::randn_like(p.value());
  for (const auto& q : a->encoder->model->named_buffers()) resnet[q.key()] = q.value().clone();
  io::write_npz(dir / "resnet18.npz", resnet);
  load_pretrained_encoder(*b->encoder, dir / "resnet18.npz");
  CHECK(torch::equal(b->encoder->model->conv1->weight, resnet.at("conv1.weight")));
  resnet.erase("layer1.0.conv1.weight");
  io::write_npz(dir / "broken.npz", resnet);
  CHECK_THROWS_WITH(load_pretrained_encoder(*b->encoder, dir / "broken.npz"),
                    Catch::Contains("layer1.0.conv1.weight"));
}

TEST_CASE("the default token PE is the reference's addcmul table, bit for bit",
          "[pipeline][checkpoint][parity]") {
  // METHOD 3.2 [parity]: PyTorch's addcmul rounds x * f + phase once; at frequencies up to
  // 2^31 pi that decides the value. The table here is computed by the installed PyTorch.
  torch::manual_seed(2);
  const auto x = (torch::rand({300, 3}) * 2 - 1) * 0.9;
  test::PythonReference py("pe_fused_table");
  py.add("x", x);
  const auto table = py.run("pe_fused").at("pe32");
  const TransHE vit(TransHEConfig{});
  const auto ours = vit->encode_positions(x);
  REQUIRE(ours.sizes() == table.sizes());
  CHECK(torch::equal(ours, table));
  // The separately rounded form (the old default) is another table.
  TransHEConfig separate;
  separate.pe_rounding = PeRounding::separate;
  const auto other = TransHE(separate)->encode_positions(x);
  CHECK((other != table).sum().item<int64_t>() > 100);
}

TEST_CASE("a reference checkpoint renders the independent Python reference's rays end to end",
          "[pipeline][checkpoint][parity]") {
  // The Python side (tests/python/model_reference.py render, written from docs/METHOD.md in
  // PyTorch) loads the .pth that torch.save wrote and renders the rays of a small frame; the C++
  // import of the same file, with the default configuration, must give the same density, colour,
  // acc and depth per ray.
  const auto& dir = fixtures();
  const auto f = test::synthetic_frame(300, 24, 3, 32, 4);
  auto rays = test::target_rays(f, 16);
  const auto pick = torch::arange(0, rays.size(), std::max<int64_t>(1, rays.size() / 40));
  rays = rays.index(pick);
  REQUIRE(rays.size() >= 20);

  TransHuman model(ModelConfig{});
  import_reference_checkpoint(*model, dir / "full.pth");
  model->eval();
  torch::NoGradGuard no_grad;
  const RenderConfig rc;  // defaults: 64 samples, progressive
  const auto cache = prepare_frame(*model, f.inputs, rc);
  const auto ours = th::pipeline::render(*model, cache, rays, rc, th::pipeline::kInference);
  // Raw density of every sample (culled samples compared as 0 below).
  const int64_t S = rc.samples;
  const auto t = torch::linspace(0, 1, S);
  const auto z = rays.near.unsqueeze(1) * (1 - t) + rays.far.unsqueeze(1) * t;
  const auto pts =
      (rays.origins.unsqueeze(1) + rays.directions.unsqueeze(1) * z.unsqueeze(2)).reshape({-1, 3});
  const auto dirs = rays.directions.unsqueeze(1).expand({-1, S, 3}).reshape({-1, 3});
  const auto sigma = model->forward(cache, pts, dirs).select(1, 3).view({-1, S});

  test::PythonReference py("render_end_to_end");
  const auto& in = f.inputs;
  for (const auto& [name, tensor] : std::vector<std::pair<std::string, torch::Tensor>>{
           {"ref_images", in.ref_images},
           {"K", in.K},
           {"R", in.R},
           {"T", in.T},
           {"vertices", in.vertices},
           {"Rh", in.Rh},
           {"Th", in.Th},
           {"A", in.A},
           {"canonical", in.canonical},
           {"visibility", in.visibility.to(torch::kLong)},
           {"labels", in.labels},
           {"origins", rays.origins},
           {"directions", rays.directions},
           {"near", rays.near},
           {"far", rays.far},
           {"samples", torch::tensor({S})},
           {"cull", torch::tensor({rc.cull_distance}, torch::kDouble)}})
    py.add(name, tensor);
  std::ofstream((py.dir() / "checkpoint.txt").string()) << (dir / "full.pth").string();
  const auto ref = py.run("render");

  const auto kept = ref.at("kept").to(torch::kBool);
  INFO(rays.size() << " rays, " << kept.sum().item<int64_t>() << " of " << kept.numel()
                   << " samples near the body");
  REQUIRE(kept.any().item<bool>());
  const auto sigma_diff = (torch::where(kept, sigma, torch::zeros_like(sigma)) - ref.at("sigma"))
                              .abs()
                              .max()
                              .item<double>();
  const auto rgb_diff = (ours.rgb - ref.at("rgb")).abs().max().item<double>();
  const auto acc_diff = (ours.acc - ref.at("acc")).abs().max().item<double>();
  const auto depth_diff = (ours.depth - ref.at("depth")).abs().max().item<double>();
  INFO("max |diff|: sigma " << sigma_diff << ", rgb " << rgb_diff << ", acc " << acc_diff
                            << ", depth " << depth_diff);
  CHECK(sigma_diff <= 1e-5);
  CHECK(rgb_diff <= 1e-5);
  CHECK(acc_diff <= 1e-5);
  CHECK(depth_diff <= 1e-5);
  // Not a vacuous comparison: the rays carry opacity and colour well above the tolerance.
  CHECK(ref.at("acc").max().item<double>() > 0.01);
  CHECK(ref.at("rgb").max().item<double>() > 0.005);
  CHECK(ref.at("sigma").abs().max().item<double>() > 0.1);
}
