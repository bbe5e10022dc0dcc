#pragma once
// Every checkpoint this project reads or writes (METHOD 5, 8):
// - a training checkpoint (.pt, torch::serialize archive): model weights and buffers, the model
//   config that trained them, Adam's state and the run's position; written atomically, read
//   checked (pipeline/checked_load.hpp), also sent as bytes from rank 0 to the other ranks;
// - model weights alone (save_model_weights / load_model_weights);
// - load_weights, what evaluation and inference call: ours (.pt) or the reference
//   implementation's (.pth, pipeline/reference_import.hpp).

#include <torch/optim/adam.h>

#include <cstdint>
#include <filesystem>
#include <string>

namespace th::model {
class TransHumanImpl;
}

namespace th::pipeline {

// The position of a run, stored beside the weights.
struct CheckpointState {
  int epoch = 0;      // epoch to continue with
  int64_t step = 0;   // global steps done
  int iteration = 0;  // iterations done within `epoch`
};

// Writes a training checkpoint to `path` atomically (in memory, then a temporary file renamed
// over the target: never half-written; a full disk is an error naming the file).
void save_checkpoint(const std::filesystem::path& path, model::TransHumanImpl& model,
                     torch::optim::Adam& optim, const CheckpointState& state);
// Reads one into `model` and `optim`, checked; th::Error naming the file.
CheckpointState load_checkpoint(const std::filesystem::path& path, model::TransHumanImpl& model,
                                torch::optim::Adam& optim);

// The same archive as bytes (data-parallel start: rank 0's state for every rank), and back.
std::string checkpoint_bytes(model::TransHumanImpl& model, torch::optim::Adam& optim,
                             const CheckpointState& state);
CheckpointState restore_checkpoint_bytes(const std::string& bytes, model::TransHumanImpl& model,
                                         torch::optim::Adam& optim, const std::string& source);

// Loads the weights of a checkpoint into `model`: ours (.pt, written by training) or the
// reference implementation's (.pth, METHOD 8). Every tensor is checked (checked_load.hpp); a
// checkpoint trained with other model.* values is refused naming them, or with
// `allow_model_mismatch` (eval.model_mismatch: warn) loaded with a warning. Throws th::Error
// naming the file.
void load_weights(model::TransHumanImpl& model, const std::filesystem::path& checkpoint,
                  bool allow_model_mismatch = false);

// This project's model weights alone (parameters and buffers by name, and the model config).
void save_model_weights(const model::TransHumanImpl& model, const std::filesystem::path& path);
void load_model_weights(model::TransHumanImpl& model, const std::filesystem::path& path);

}  // namespace th::pipeline
