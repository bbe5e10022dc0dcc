// Checkpoints are read without trusting them: records, views, values, names, shapes
// and the model settings they were trained with.
#include <torch/torch.h>

#include <catch2/catch.hpp>
#include <cstring>
#include <fstream>

#include "core/config_io.hpp"
#include "core/error.hpp"
#include "io/files.hpp"
#include "io/zip.hpp"
#include "model/transhuman.hpp"
#include "pipeline/checked_load.hpp"
#include "pipeline/checkpoint.hpp"
#include "pipeline/pipeline.hpp"
#include "support/test_env.hpp"
#include "support/tiny_config.hpp"
#include "train/trainer.hpp"

namespace fs = std::filesystem;
using th::Error;

namespace {

th::Config tiny_config(std::vector<std::string> overrides = {}) {
  return th::test::tiny_train_config(std::move(overrides));
}

th::model::TransHuman make_model(const th::Config& c) {
  torch::manual_seed(3);
  return th::model::TransHuman(c.model);
}

// Our checkpoint layout with the model alone (every record is a weight), optionally without
// the stored model config (a checkpoint written before it was stored).
void save_model_only(th::model::TransHumanImpl& model, const fs::path& file, bool with_config) {
  torch::serialize::OutputArchive root, m;
  model.save(m);
  root.write("model", m);
  if (with_config) th::pipeline::write_model_config(root, model.config());
  root.save_to(file.string());
}

// Rewrites the zip `file` with `edit` applied to its members (stored, as PyTorch writes).
void rewrite_zip(
    const fs::path& file,
    const std::function<void(std::vector<std::pair<std::string, std::string>>&)>& edit) {
  std::vector<std::pair<std::string, std::string>> members;
  for (auto& m : th::io::read_zip(th::io::read_file(file), file.string()))
    members.emplace_back(m.name, std::move(m.data));
  edit(members);
  th::io::write_file_atomic(file, th::io::write_zip(members));
}

std::string error_of(const std::function<void()>& fn) {
  try {
    fn();
  } catch (const Error& e) {
    return e.what();
  }
  return "(no error)";
}

}  // namespace

TEST_CASE("a checkpoint's weights load back exactly through the checked reader",
          "[pipeline][checkpoint]") {
  const auto c = tiny_config();
  auto a = make_model(c);
  const fs::path dir = th::test::scratch_dir("ckcheck_roundtrip");
  save_model_only(*a, dir / "a.pt", true);
  torch::manual_seed(99);
  th::model::TransHuman b(c.model);
  th::pipeline::load_weights(*b, dir / "a.pt");
  const auto pa = a->named_parameters(), pb = b->named_parameters();
  for (const auto& p : pa) CHECK(torch::equal(p.value(), pb[p.key()]));
}

TEST_CASE("a storage record truncated inside a valid zip is refused, naming the file",
          "[pipeline][checkpoint]") {
  const auto c = tiny_config();
  auto model = make_model(c);
  const fs::path dir = th::test::scratch_dir("ckcheck_truncated"), file = dir / "cut.pt";
  save_model_only(*model, file, true);
  std::string cut;
  size_t largest_bytes = 0;
  rewrite_zip(file, [&](auto& members) {
    size_t largest = 0, best = 0;
    for (size_t i = 0; i < members.size(); ++i)
      if (members[i].first.find("/data/") != std::string::npos &&
          members[i].second.size() > largest)
        largest = members[best = i].second.size();
    REQUIRE(largest > 64);
    cut = members[best].first;
    largest_bytes = largest;
    members[best].second.resize(largest / 2);
  });
  INFO("truncated " << cut);
  auto other = make_model(c);
  const std::string message = error_of([&] { th::pipeline::load_weights(*other, file); });
  CHECK_THAT(message, Catch::Contains(file.string()));
  CHECK_THAT(message, Catch::Contains(file.string() + "/" + cut + ": a storage record of " +
                                      std::to_string(largest_bytes / 2) + " bytes where ") &&
                          Catch::Contains(" elements of 4 bytes are claimed"));
}

TEST_CASE("non-finite weights are refused naming the tensor and the index",
          "[pipeline][checkpoint]") {
  const auto c = tiny_config();
  auto model = make_model(c);
  {
    torch::NoGradGuard no_grad;
    model->heads->alpha_fc->weight[0][5] = std::nanf("");
  }
  const fs::path dir = th::test::scratch_dir("ckcheck_nan"), file = dir / "nan.pt";
  save_model_only(*model, file, true);
  auto other = make_model(c);
  const std::string message = error_of([&] { th::pipeline::load_weights(*other, file); });
  CHECK_THAT(message, Catch::Contains("heads.alpha_fc.weight") && Catch::Contains("NaN") &&
                          Catch::Contains("[0, 5]") && Catch::Contains(file.string()));
}

TEST_CASE("compressed storage records and inflated claims are refused from the zip directory alone",
          "[pipeline][checkpoint]") {
  const fs::path dir = th::test::scratch_dir("ckcheck_deflate"), file = dir / "packed.pt";
  // Stored zips whose method fields say deflate (a repacked file; a zip bomb claiming gigabytes):
  // nothing is inflated or allocated.
  auto write = [&](const std::string& member, uint32_t claimed) {
    const std::string empty_dict_pickle("\x80\x02}q\x00.", 6);
    std::string zip = th::io::write_zip({{"archive/version", "3\n"},
                                         {"archive/data.pkl", empty_dict_pickle},
                                         {member, std::string(100, 'x')}});
    // The member's local header and central directory entry: method 8, `claimed` bytes.
    auto patch = [&](uint32_t signature, size_t method_at, size_t size_at, size_t name_at) {
      const std::string sig(reinterpret_cast<const char*>(&signature), 4);
      for (size_t p = 0; (p = zip.find(sig, p)) != std::string::npos; ++p) {
        if (zip.compare(p + name_at, member.size(), member) != 0) continue;
        zip[p + method_at] = 8;
        std::memcpy(&zip[p + size_at], &claimed, 4);
      }
    };
    patch(0x04034b50, 8, 22, 30);   // local header: method, uncompressed size, name
    patch(0x02014b50, 10, 24, 46);  // central directory
    th::io::write_file_atomic(file, zip);
  };
  write("archive/data/0", 100);
  CHECK_THAT(
      error_of([&] { th::pipeline::check_checkpoint_archive(file); }),
      Catch::Contains("packed.pt/archive/data/0") && Catch::Contains("compressed storage record"));
  auto model = make_model(tiny_config());
  CHECK_THAT(error_of([&] { th::pipeline::load_weights(*model, file); }),
             Catch::Contains("compressed storage record"));
  write("archive/data.pkl", 0x7fffffff);
  CHECK_THAT(error_of([&] { th::pipeline::check_checkpoint_archive(file); }),
             Catch::Contains("archive/data.pkl") && Catch::Contains("claiming 2147483647 bytes"));
  write("archive/code/__torch__.py", 200);  // LibTorch's own small compressed code files pass
  CHECK_NOTHROW(th::pipeline::check_checkpoint_archive(file));
  // LibTorch's reader is not opened on a zip that is not a checkpoint.
  th::io::write_file_atomic(
      file, th::io::write_zip({{"archive/data.pkl", std::string("\x80\x02}q\x00.", 6)}}));
  CHECK_THAT(error_of([&] { th::pipeline::check_checkpoint_archive(file); }),
             Catch::Contains("not a PyTorch checkpoint (no <archive>/version record)"));
}

TEST_CASE("tensor views are checked against their storage", "[pipeline][checkpoint]") {
  using th::pipeline::check_view;
  CHECK_NOTHROW(check_view({2, 3}, {3, 1}, 0, 6, "v"));
  CHECK_NOTHROW(check_view({3, 2}, {1, 3}, 0, 6, "v"));              // transposed
  CHECK_NOTHROW(check_view({0, 1000000}, {1000000, 1}, 0, 0, "v"));  // empty
  CHECK_THAT(error_of([] {
               check_view({2, 3}, {3, 1}, 1, 6, "t.pt: a tensor");
             }),
             Catch::Contains("t.pt: a tensor") && Catch::Contains("needs 7 elements"));
  CHECK_THAT(error_of([] { check_view({4}, {-1}, 3, 6, "v"); }),
             Catch::Contains("has a negative size or stride"));
  CHECK_THAT(error_of([] { check_view({-4}, {1}, 0, 6, "v"); }),
             Catch::Contains("has a negative size or stride"));
  CHECK_THAT(error_of([] { check_view({2}, {1}, -1, 6, "v"); }),
             Catch::Contains("before its storage"));
  // A 500-byte file must not become gigabytes: a stride-0 expansion is refused.
  CHECK_THAT(error_of([] {
               check_view({1000000000, 1000}, {0, 0}, 0, 6, "v");
             }),
             Catch::Contains("views 1000000000000 elements of a storage of 6"));
  CHECK_THAT(error_of([] {
               check_view({int64_t{1} << 40, int64_t{1} << 40}, {1, 1}, 0, 6, "v");
             }),
             Catch::Contains("has more elements than can be counted"));
  CHECK_THAT(error_of([] { check_view({3}, {int64_t{1} << 62}, 0, 6, "v"); }),
             Catch::Contains("reaches past any storage"));
  CHECK_THAT(error_of([] {
               check_view({2, 3}, {3}, 0, 6, "v");
             }),
             Catch::Contains("has 1 stride(s) for 2 size(s)"));
}

TEST_CASE(
    "a checkpoint of other model settings names the keys, and eval.model_mismatch=warn goes on",
    "[pipeline][checkpoint]") {
  const auto c = tiny_config();
  auto model = make_model(c);
  const fs::path dir = th::test::scratch_dir("ckcheck_settings");
  save_model_only(*model, dir / "stored.pt", true);

  const auto other = tiny_config({"model.dparf.nk=2", "model.grouping.num_tokens=20"});
  auto b = make_model(other);
  const std::string message = error_of([&] { th::pipeline::load_weights(*b, dir / "stored.pt"); });
  CHECK_THAT(message, Catch::Contains("model.dparf.nk: checkpoint 3, config 2") &&
                          Catch::Contains("model.grouping.num_tokens: checkpoint 24, config 20") &&
                          Catch::Contains("eval.model_mismatch=warn"));
  CHECK_NOTHROW(th::pipeline::load_weights(*b, dir / "stored.pt", /*allow_model_mismatch=*/true));
  CHECK(torch::equal(b->heads->alpha_fc->weight, model->heads->alpha_fc->weight));

  // A checkpoint without a stored config: its run's config.yaml (two folders up) is compared.
  fs::create_directories(dir / "run" / "checkpoints");
  save_model_only(*model, dir / "run" / "checkpoints" / "old.pt", false);
  th::config::write_yaml(dir / "run" / "config.yaml",
                         th::config::to_tree(tiny_config({"model.dparf.nk=5"})));
  CHECK_THAT(
      error_of([&] { th::pipeline::load_weights(*model, dir / "run" / "checkpoints" / "old.pt"); }),
      Catch::Contains("model.dparf.nk: run config 5, config 3"));
  // A run config written when model.* still had its execution keys: they are not compared.
  auto old_tree = th::config::to_tree(tiny_config());
  old_tree["model"]["exact_shortcuts"] = false;
  old_tree["model"]["readout_windows"] = false;
  old_tree["model"]["encoder"]["fast_sampling"] = false;
  th::config::write_yaml(dir / "run" / "config.yaml", old_tree);
  CHECK_NOTHROW(th::pipeline::load_weights(*model, dir / "run" / "checkpoints" / "old.pt"));
  // Without either, only shapes can be checked.
  save_model_only(*model, dir / "bare.pt", false);
  CHECK_NOTHROW(th::pipeline::load_weights(*b, dir / "bare.pt"));
}

TEST_CASE("missing, extra and reshaped parameters name the config key that decides them",
          "[pipeline][checkpoint]") {
  const fs::path dir = th::test::scratch_dir("ckcheck_shapes");
  auto load_into = [&](const th::Config& saved, const th::Config& wanted) {
    auto a = make_model(saved);
    save_model_only(*a, dir / "x.pt", false);
    torch::serialize::InputArchive root, m;
    root.load_from((dir / "x.pt").string());
    root.read("model", m);
    auto b = make_model(wanted);
    return error_of([&] { th::pipeline::load_module_checked(*b, m, "x.pt"); });
  };
  const auto one = tiny_config(), two = tiny_config({"model.transhe.depth=2"});
  CHECK_THAT(load_into(two, one), Catch::Contains("holds module 'human.ViT.blocks.1'") &&
                                      Catch::Contains("model.transhe.depth"));
  CHECK_THAT(load_into(one, two), Catch::Contains("has no module 'human.ViT.blocks.1'") &&
                                      Catch::Contains("model.transhe.depth"));
  CHECK_THAT(
      load_into(one, tiny_config({"model.fdi.raw_rgb=false"})),
      Catch::Contains("encoder.reduction_layer.weight") && Catch::Contains("model.fdi.raw_rgb"));
  CHECK_THAT(load_into(one, tiny_config({"model.fdi.appearance=false"})),
             Catch::Contains("fdi.alpha_res_0") && Catch::Contains("model.fdi.appearance"));
  // Nothing was half-copied: a failed load leaves the model as it was.
  auto b = make_model(one);
  const auto before = b->heads->alpha_fc->weight.clone();
  auto a = make_model(two);
  {
    torch::NoGradGuard no_grad;
    a->heads->alpha_fc->weight.fill_(7);
  }
  save_model_only(*a, dir / "y.pt", false);
  CHECK_THROWS_AS(th::pipeline::load_weights(*b, dir / "y.pt"), Error);
  CHECK(torch::equal(b->heads->alpha_fc->weight, before));
}

TEST_CASE("a resumed run's optimiser state must be finite too", "[pipeline][checkpoint]") {
  torch::set_num_threads(1);
  const auto c = tiny_config({"train.val_views=0"});
  const fs::path run = th::test::scratch_dir("ckcheck_adam"),
                 latest = run / "checkpoints" / "latest.pt";
  th::train::train(c, torch::kCPU, {run, false, 1});
  // The same checkpoint with a NaN in Adam's first moment (trainer.cpp's layout).
  torch::serialize::InputArchive root, m, o;
  root.load_from(latest.string());
  root.read("model", m);
  root.read("optimizer", o);
  auto model = make_model(c);
  model->load(m);
  torch::optim::Adam optim(model->parameters(), torch::optim::AdamOptions(c.train.lr));
  optim.load(o);
  REQUIRE_FALSE(optim.state().empty());
  {
    auto& state = static_cast<torch::optim::AdamParamState&>(*optim.state().begin()->second);
    torch::NoGradGuard no_grad;
    state.exp_avg().view(-1)[0] = std::nanf("");
  }
  torch::serialize::OutputArchive out, m2, o2;
  model->save(m2);
  optim.save(o2);
  out.write("model", m2);
  th::pipeline::write_model_config(out, model->config());
  out.write("optimizer", o2);
  for (const char* key : {"epoch", "step", "iteration"}) {
    torch::Tensor t;
    root.read(key, t);
    out.write(key, t);
  }
  out.save_to(latest.string());
  CHECK_THAT(error_of([&] {
               th::train::train(c, torch::kCPU, {run, true, 2});
             }),
             Catch::Contains("optimiser state exp_avg") && Catch::Contains("NaN") &&
                 Catch::Contains("latest.pt"));
}

namespace {

// Canonical points for a grouping of the tiny config (24 tokens): a seeded cloud.
torch::Tensor cloud(int64_t n = 240) {
  torch::manual_seed(11);
  return torch::rand({n, 3}, torch::kFloat64);
}

// A training checkpoint of `model` (weights, config, token groups, Adam, position).
void save_training_checkpoint(th::model::TransHumanImpl& model, const fs::path& file) {
  torch::optim::Adam optim(model.parameters(), torch::optim::AdamOptions(1e-3));
  th::pipeline::save_checkpoint(file, model, optim, {});
}

}  // namespace

TEST_CASE("the token groups travel with every checkpoint and are used as stored",
          "[pipeline][checkpoint][tokens]") {
  const fs::path dir = th::test::scratch_dir("ckcheck_tokens");
  auto c = tiny_config();
  c.model.grouping.cache_dir =
      (dir / "cache").string();  // (tiny_config sets the shared cache last)
  auto a = make_model(c);
  // A model without groups cannot be written: a run makes them first.
  CHECK_THAT(error_of([&] { save_training_checkpoint(*a, dir / "none.pt"); }),
             Catch::Contains("no token groups"));
  th::pipeline::Tokens made(*a, cloud());  // the run's start: k-means, stored in the model
  const auto labels = a->token_groups().labels;
  REQUIRE(labels.defined());
  CHECK(a->token_groups().origin == "canonical_kmeans num_tokens=24 seed=0");
  save_training_checkpoint(*a, dir / "a.pt");
  th::pipeline::save_model_weights(*a, dir / "weights.pt");

  // Read back with the k-means cache gone: the stored labels, no k-means run.
  fs::remove_all(dir / "cache");
  auto b = make_model(c);
  th::pipeline::load_weights(*b, dir / "a.pt");
  CHECK(torch::equal(b->token_groups().labels, labels));
  CHECK(b->token_groups().origin == a->token_groups().origin);
  th::pipeline::Tokens used(*b, cloud());
  CHECK_FALSE(fs::exists(dir / "cache"));
  auto w = make_model(c);
  th::pipeline::load_model_weights(*w, dir / "weights.pt");
  CHECK(torch::equal(w->token_groups().labels, labels));

  // Another seed in the config: refused by name; with warn, the checkpoint's labels.
  auto seeded = tiny_config({"model.grouping.seed=7"});
  seeded.model.grouping.cache_dir = (dir / "cache").string();
  auto s = make_model(seeded);
  CHECK_THAT(error_of([&] { th::pipeline::load_weights(*s, dir / "a.pt"); }),
             Catch::Contains("model.grouping.seed: checkpoint 0, config 7"));
  th::pipeline::load_weights(*s, dir / "a.pt", /*allow_model_mismatch=*/true);
  th::pipeline::Tokens warned(*s, cloud());
  CHECK(torch::equal(s->token_groups().labels, labels));
  // Not vacuous: seed 7 groups the same points otherwise.
  auto fresh = make_model(seeded);
  th::pipeline::Tokens other(*fresh, cloud());
  CHECK_FALSE(torch::equal(fresh->token_groups().labels, labels));

  // Stored labels that do not fit the body model are refused, naming both counts.
  auto small = make_model(c);
  th::pipeline::load_weights(*small, dir / "a.pt");
  CHECK_THAT(error_of([&] { th::pipeline::Tokens t(*small, cloud(100)); }),
             Catch::Contains("label 240 vertices; the body model (data.smpl_model) has 100"));
}

TEST_CASE("a checkpoint written before checkpoints stored their groups loads, computing them",
          "[pipeline][checkpoint][tokens]") {
  const fs::path dir = th::test::scratch_dir("ckcheck_tokens_old");
  auto c = tiny_config();
  c.model.grouping.cache_dir =
      (dir / "cache").string();  // (tiny_config sets the shared cache last)
  auto a = make_model(c);
  save_model_only(*a, dir / "old.pt", true);  // the layout before: no token_groups
  auto b = make_model(c);
  th::pipeline::load_weights(*b, dir / "old.pt");
  CHECK(b->token_groups().empty());
  th::pipeline::Tokens tokens(*b, cloud());
  CHECK(b->token_groups().labels.defined());
  CHECK(fs::exists(dir / "cache"));  // computed (and cached) as a run would
}

TEST_CASE("broken stored token groups are refused naming the file and the entry",
          "[pipeline][checkpoint][tokens]") {
  const fs::path dir = th::test::scratch_dir("ckcheck_tokens_bad");
  auto c = tiny_config();
  c.model.grouping.cache_dir =
      (dir / "cache").string();  // (tiny_config sets the shared cache last)
  auto a = make_model(c);
  auto write = [&](const std::string& name, const c10::IValue& origin,
                   const torch::Tensor& labels) {
    torch::serialize::OutputArchive root, m;
    a->save(m);
    root.write("model", m);
    th::pipeline::write_model_config(root, a->config());
    root.write("token_groups", origin);
    if (labels.defined()) root.write("token_labels", labels, true);
    root.save_to((dir / name).string());
    return dir / name;
  };
  const auto origin = c10::IValue(std::string("canonical_kmeans num_tokens=24 seed=0"));
  auto load = [&](const fs::path& file) {
    auto b = make_model(c);
    return error_of([&] { th::pipeline::load_weights(*b, file); });
  };
  const auto range = write("range.pt", origin, torch::tensor({0, 1, 9}, torch::kInt64));
  CHECK_THAT(load(range), Catch::Contains(range.string() + ": token_labels") &&
                              Catch::Contains("run from 0 to 9"));
  CHECK_THAT(load(write("hole.pt", origin, torch::tensor({0, 2, 2}, torch::kInt64))),
             Catch::Contains("1 of the 3 tokens hold no vertex"));
  CHECK_THAT(load(write("float.pt", origin, torch::rand({5}))), Catch::Contains("1-D int64"));
  CHECK_THAT(load(write("nolabels.pt", origin, {})),
             Catch::Contains("without their labels 'token_labels'"));
  CHECK_THAT(load(write("perframe.pt", origin, torch::zeros({0}, torch::kInt64))),
             Catch::Contains("grouped per frame") &&
                 Catch::Contains("model.grouping.kind is canonical_kmeans"));
}
