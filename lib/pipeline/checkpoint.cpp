#include "pipeline/checkpoint.hpp"

#include <spdlog/spdlog.h>
#include <torch/torch.h>

#include <sstream>

#include "body/grouping.hpp"
#include "core/config_io.hpp"
#include "core/error.hpp"
#include "io/files.hpp"
#include "model/transhuman.hpp"
#include "pipeline/checked_load.hpp"
#include "pipeline/reference_import.hpp"

namespace th::pipeline {
namespace fs = std::filesystem;

namespace {

// An archive serialised in memory. Every file is then written by write_file_atomic: a failing
// write (disk full) is an error naming the file and leaves no partial file, where LibTorch's own
// file writer would throw from its destructor and terminate the process.
std::string archive_bytes(torch::serialize::OutputArchive& archive, const std::string& what) {
  std::ostringstream out;
  try {
    archive.save_to(out);
  } catch (const c10::Error& e) {
    fail("cannot serialise ", what, ": ", e.what_without_backtrace());
  }
  return out.str();
}

// The token groups (model/inputs.hpp) beside the weights: their origin as text and their labels
// ((0) for a grouping made per frame).
constexpr const char* kTokenOrigin = "token_groups";
constexpr const char* kTokenLabels = "token_labels";

void write_token_groups(torch::serialize::OutputArchive& archive,
                        const model::TransHumanImpl& model, const std::string& what) {
  const auto& groups = model.token_groups();
  if (groups.empty())
    fail("cannot write ", what,
         ": the model has no token groups yet (a run computes them at its start)");
  archive.write(kTokenOrigin, c10::IValue(groups.origin));
  archive.write(kTokenLabels,
                groups.labels.defined() ? groups.labels : torch::zeros({0}, torch::kInt64),
                /*is_buffer=*/true);
}

// Sets the model's token groups from the archive. A checkpoint written before checkpoints carried
// them loads with one warning: the labels are then computed from model.grouping when a frame is
// first prepared (pipeline::Tokens).
void read_token_groups(torch::serialize::InputArchive& archive, model::TransHumanImpl& model,
                       const std::string& source) {
  c10::IValue origin;
  if (!archive.try_read(kTokenOrigin, origin)) {
    spdlog::warn(
        "{}: written before checkpoints stored their token groups; they are computed again from "
        "model.grouping ({}), which gives the trained groups only where the k-means runs as it "
        "did in training",
        source, body::describe(model.config().grouping));
    model.set_token_groups({});
    return;
  }
  if (!origin.isString() || origin.toStringRef().empty())
    fail(source, ": '", kTokenOrigin, "' is not a description of token groups");
  torch::Tensor labels;
  if (!archive.try_read(kTokenLabels, labels, /*is_buffer=*/true))
    fail(source, ": stores token groups (", origin.toStringRef(), ") without their labels '",
         kTokenLabels, "'");
  model::TokenGroups groups{{}, origin.toStringRef()};
  if (labels.numel() > 0) {
    check_loaded_tensor(labels, source, kTokenLabels);
    body::check_labels(labels, source + ": " + kTokenLabels);
    groups.labels = labels.to(torch::kCPU).clone();
  } else if (model.config().grouping.kind != GroupingKind::observation_grid) {
    fail(source, ": its tokens are grouped per frame (", groups.origin,
         "), model.grouping.kind is ", config::name_of(model.config().grouping.kind),
         ": use the run's config.yaml as --config");
  }
  model.set_token_groups(std::move(groups));
}

// The checkpoint archive: model weights and buffers, optimiser state and the run's position.
void write_checkpoint(torch::serialize::OutputArchive& root, model::TransHumanImpl& model,
                      torch::optim::Adam& optim, const CheckpointState& st) {
  torch::serialize::OutputArchive m, o;
  model.save(m);
  optim.save(o);
  root.write("model", m);
  write_model_config(root, model.config());
  write_token_groups(root, model, "a checkpoint");
  root.write("optimizer", o);
  root.write("epoch", torch::tensor(int64_t(st.epoch)));
  root.write("step", torch::tensor(st.step));
  root.write("iteration", torch::tensor(int64_t(st.iteration)));
}

CheckpointState read_checkpoint(torch::serialize::InputArchive& root, model::TransHumanImpl& model,
                                torch::optim::Adam& optim, const std::string& source) {
  torch::serialize::InputArchive m, o;
  root.read("model", m);
  root.read("optimizer", o);
  load_module_checked(model, m, source);
  read_token_groups(root, model, source);
  optim.load(o);
  for (const auto& entry : optim.state()) {  // Adam's moments resume the run: finite too
    const auto& state = static_cast<const torch::optim::AdamParamState&>(*entry.second);
    check_finite(state.exp_avg(), source + ": optimiser state exp_avg");
    check_finite(state.exp_avg_sq(), source + ": optimiser state exp_avg_sq");
  }
  torch::Tensor epoch, step, iteration;
  root.read("epoch", epoch);
  root.read("step", step);
  root.read("iteration", iteration);
  return {int(epoch.item<int64_t>()), step.item<int64_t>(), int(iteration.item<int64_t>())};
}

}  // namespace

void save_checkpoint(const fs::path& path, model::TransHumanImpl& model, torch::optim::Adam& optim,
                     const CheckpointState& st) {
  torch::serialize::OutputArchive root;
  write_checkpoint(root, model, optim, st);
  io::write_file_atomic(path, archive_bytes(root, "checkpoint '" + path.string() + "'"));
}

CheckpointState load_checkpoint(const fs::path& path, model::TransHumanImpl& model,
                                torch::optim::Adam& optim) {
  if (!fs::exists(path)) fail("cannot resume: '", path.string(), "' does not exist");
  check_checkpoint_archive(path);
  torch::serialize::InputArchive root;
  try {
    root.load_from(path.string());
    return read_checkpoint(root, model, optim, path.string());
  } catch (const c10::Error& e) {
    fail("checkpoint '", path.string(), "' cannot be read: ", e.what_without_backtrace());
  }
}

std::string checkpoint_bytes(model::TransHumanImpl& model, torch::optim::Adam& optim,
                             const CheckpointState& state) {
  torch::serialize::OutputArchive root;
  write_checkpoint(root, model, optim, state);
  return archive_bytes(root, "rank 0's state");
}

CheckpointState restore_checkpoint_bytes(const std::string& bytes, model::TransHumanImpl& model,
                                         torch::optim::Adam& optim, const std::string& source) {
  torch::serialize::InputArchive root;
  try {
    root.load_from(bytes.data(), bytes.size());
  } catch (const c10::Error& e) {
    fail(source, " cannot be read: ", e.what_without_backtrace());
  }
  return read_checkpoint(root, model, optim, source);
}

namespace {

// The token groups of a reference checkpoint: its repository's k-means labels
// (model.grouping.kmeans_file), or, on the user's explicit word ("compute"), groups computed here.
void import_reference_groups(model::TransHumanImpl& model, const fs::path& checkpoint) {
  const auto& g = model.config().grouping;
  if (g.kind != GroupingKind::canonical_kmeans)
    fail("'", checkpoint.string(), "' is a reference checkpoint, whose tokens are k-means groups: ",
         "model.grouping.kind must be canonical_kmeans, not ", config::name_of(g.kind));
  if (g.kmeans_file.empty())
    fail("'", checkpoint.string(),
         "' is a reference checkpoint: it needs the token groups it was trained with. "
         "Set model.grouping.kmeans_file to the reference repository's kmeans_dict/kmeans_dict_",
         g.num_tokens, ".npy, or to '", kKMeansCompute,
         "' to go on with groups computed here (renders will "
         "differ from the reference's)");
  if (g.kmeans_file == kKMeansCompute) {
    spdlog::warn(
        "{}: model.grouping.kmeans_file is '{}': the reference's network reads tokens grouped by "
        "this project's k-means ({}), not those it was trained with; results will differ from the "
        "reference's",
        checkpoint.string(), kKMeansCompute, body::describe(g));
    model.set_token_groups({});
    return;
  }
  auto labels = body::load_reference_kmeans(g.kmeans_file, -1);
  body::check_labels(labels, g.kmeans_file);
  model.set_token_groups({labels, body::describe(g)});
}

}  // namespace

void load_weights(model::TransHumanImpl& model, const fs::path& checkpoint,
                  bool allow_model_mismatch) {
  if (!fs::exists(checkpoint)) fail("checkpoint '", checkpoint.string(), "' does not exist");
  if (checkpoint.extension() == ".pth") {
    const auto report = import_reference_checkpoint(model, checkpoint);
    import_reference_groups(model, checkpoint);
    spdlog::info("imported {} tensors of the reference checkpoint {}", report.loaded.size(),
                 checkpoint.string());
    return;
  }
  check_checkpoint_archive(checkpoint);
  torch::serialize::InputArchive root, m;
  try {
    root.load_from(checkpoint.string());
    root.read("model", m);
  } catch (const c10::Error& e) {
    fail("checkpoint '", checkpoint.string(), "' cannot be read: ", e.what_without_backtrace());
  }
  // Another model configuration: different shapes fail below naming the parameter; different
  // values of shape-neutral keys (nk, num_tokens, ...) would silently compute something else.
  const auto changed = model_config_differences(root, checkpoint, model.config());
  if (!changed.empty()) {
    std::string list;
    for (const auto& c : changed) list += (list.empty() ? "" : "; ") + c;
    if (!allow_model_mismatch)
      fail("checkpoint '", checkpoint.string(), "' was trained with other model settings (", list,
           "): use the run's config.yaml as --config, or eval.model_mismatch=warn to go on anyway");
    spdlog::warn("checkpoint {} was trained with other model settings: {}", checkpoint.string(),
                 list);
  }
  load_module_checked(model, m, checkpoint.string());
  read_token_groups(root, model, checkpoint.string());
}

void save_model_weights(const model::TransHumanImpl& model, const std::filesystem::path& path) {
  torch::serialize::OutputArchive archive;
  write_model_config(archive, model.config());
  write_token_groups(archive, model, "model weights '" + path.string() + "'");
  for (const auto& p : model.named_parameters()) archive.write(p.key(), p.value());
  for (const auto& b : model.named_buffers()) archive.write(b.key(), b.value(), true);
  io::write_file_atomic(path, archive_bytes(archive, "model weights '" + path.string() + "'"));
}

void load_model_weights(model::TransHumanImpl& model, const std::filesystem::path& path) {
  if (!std::filesystem::exists(path)) fail("model weights '", path.string(), "' do not exist");
  check_checkpoint_archive(path);
  torch::serialize::InputArchive archive;
  try {
    archive.load_from(path.string());
  } catch (const c10::Error& e) {
    fail(path.string(), ": cannot read model weights (", e.what_without_backtrace(), ")");
  }
  torch::NoGradGuard no_grad;
  std::vector<std::pair<torch::Tensor, torch::Tensor>> copies;  // all checked before any is copied
  auto read = [&](const std::string& name, torch::Tensor& dst, bool buffer) {
    torch::Tensor t;
    if (!archive.try_read(name, t, buffer)) fail(path.string(), ": missing tensor '", name, "'");
    check_loaded_tensor(t, path.string(), name);
    if (t.sizes() != dst.sizes())
      fail(path.string(), ": tensor '", name, "' has shape ", t.sizes(), ", the model expects ",
           dst.sizes());
    copies.emplace_back(dst, t);
  };
  for (auto& p : model.named_parameters()) read(p.key(), p.value(), false);
  for (auto& b : model.named_buffers()) read(b.key(), b.value(), true);
  for (auto& [dst, src] : copies) dst.copy_(src);
  read_token_groups(archive, model, path.string());
}

}  // namespace th::pipeline
