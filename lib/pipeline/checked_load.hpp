#pragma once
// Reading weights without trusting the file (METHOD 8): a checkpoint is a zip of stored records
// whose tensors are views into them. Before a value is copied into the model, the archive's
// members must lie inside the file, storage records must be stored (PyTorch and LibTorch never
// compress them) and LibTorch's small compressed code files are bounded, so the file cannot
// make us allocate much more than it holds; every view must lie
// inside its storage; every value must be finite; every name and shape must be the model's.
// A mismatch names the parameter and the config key that decides it.

#include <torch/serialize/archive.h>
#include <torch/types.h>

#include <filesystem>
#include <string>
#include <vector>

#include "core/config.hpp"

namespace torch::nn {
class Module;
}

namespace th::pipeline {

// Throws th::Error naming the file and the member when the zip is malformed, a member's data
// runs past the end of the file, a storage record (…/data/…) is compressed, a compressed
// member claims more than 64 MiB or more than deflate can expand to, or a storage record is not
// the size its pickle (data.pkl) claims, or <archive>/data.pkl or <archive>/version is missing.
// Reads the directory and data.pkl, not the records.
void check_checkpoint_archive(const std::filesystem::path& path);

// The element type of a pickled storage class ("torch.FloatStorage"); th::Error naming
// `source` for another.
torch::ScalarType storage_type(const std::string& cls, const std::string& source);

// Throws th::Error starting with `what` when a view of `sizes`/`strides` at `offset` reaches
// outside a storage of `storage_elements`, has negative sizes or strides, or views more elements
// than the storage holds (a stride-0 expansion: a few bytes of file would become gigabytes).
void check_view(c10::IntArrayRef sizes, c10::IntArrayRef strides, int64_t offset,
                int64_t storage_elements, const std::string& what);
// Throws th::Error starting with `what` naming the first NaN or infinite value's index.
void check_finite(const torch::Tensor& tensor, const std::string& what);

// Throws th::Error naming `source` and `name` when the tensor's view (offset, sizes, strides)
// reaches outside its storage, overlaps itself (a stride-0 expansion of a record), or when a
// floating value is NaN or infinite (the first such index is named).
void check_loaded_tensor(const torch::Tensor& tensor, const std::string& source,
                         const std::string& name);

// The config key that decides whether the model has parameter `name` (dotted module path, ours)
// and the one that decides its shape; "" where none is known.
struct ParameterKeys {
  std::string presence;
  std::string shape;
};
ParameterKeys config_keys_for(const std::string& name);

// Loads an archive in torch::nn::Module::save's layout into `module`, checked: every parameter
// and buffer present with the module's shape, every tensor valid (check_loaded_tensor), no
// parameter or submodule in the archive that the module lacks. Nothing is copied unless all of
// it is valid. `source` names the file in errors.
void load_module_checked(torch::nn::Module& module, torch::serialize::InputArchive& archive,
                         const std::string& source);

// The model section of the config that trained a checkpoint, stored in its archive as YAML text
// under "model_config" (checkpoints written before this have none).
void write_model_config(torch::serialize::OutputArchive& archive, const ModelConfig& config);

// The model keys whose values differ between `config` and the config stored in `archive` (or,
// for a checkpoint without one, the run's config.yaml two folders up from a checkpoints/ file),
// as "model.dparf.nk: checkpoint 7, config 1". Keys that do not change the trained function
// (model.encoder.pretrained, the k-means cache folder) are not compared. Empty when equal or
// when no trained config is known.
std::vector<std::string> model_config_differences(torch::serialize::InputArchive& archive,
                                                  const std::filesystem::path& checkpoint,
                                                  const ModelConfig& config);

}  // namespace th::pipeline
