#pragma once
// Checkpoints of the reference implementation (METHOD 8): .pth files in PyTorch's zip format
// (data.pkl + data/<storage> records), read without executing anything, and their tensors copied
// into our model under our names.

#include <torch/types.h>

#include <filesystem>
#include <map>
#include <string>
#include <vector>

namespace th::model {
class TransHumanImpl;
}

namespace th::pipeline {

// The tensors of a PyTorch zip checkpoint. The pickle is read by the project's safe reader
// (io/pickle.hpp) with PyTorch's storages (persistent ids), torch._utils._rebuild_tensor_v2,
// collections.OrderedDict/Counter; nothing is executed. Files of PyTorch 1.x and 2.x alike:
// storages of every dtype torch.save writes for the usual tensors (float16/bfloat16/32/64,
// int8/16/32/64, uint8, bool), a 'byteorder' record saying big (storages are byte-swapped), and
// other records (.data/serialization_id, version) that do not matter here. `entry`: the dict
// key holding the state dict ("net" for the reference's checkpoints); a file holding the state
// dict itself works too. Nested dicts are flattened with '.' like a state dict (numbers become
// 0-d tensors). Throws th::Error naming the file.
std::map<std::string, torch::Tensor> read_torch_state_dict(const std::filesystem::path& path,
                                                           const std::string& entry = "net");

struct ImportReport {
  std::vector<std::string> loaded;   // reference names copied into the model
  std::vector<std::string> ignored;  // the reference's known unused parts present in the file
};

// The reference name of each model parameter/buffer (METHOD 8), e.g. "fdi.key0.weight" ->
// "spatial_key_value_0.key_embed.weight"; Conv1d weights (out, in, 1) become Linear (out, in).
std::string reference_name(const std::string& model_name);

// Copies a reference state dict into the model. Throws th::Error naming the first missing or
// mis-shaped key, a key holding integers or booleans where the model has weights, or a key the
// reference network does not have (its known unused parts, METHOD 8, are skipped), and the
// source; nothing is modified then.
ImportReport import_reference_state(model::TransHumanImpl& model,
                                    const std::map<std::string, torch::Tensor>& state,
                                    const std::string& source);
ImportReport import_reference_checkpoint(model::TransHumanImpl& model,
                                         const std::filesystem::path& path);

}  // namespace th::pipeline
