#pragma once
// ImageNet ResNet-18 weights for the encoder (METHOD 3.1): an .npz with torchvision's resnet18
// state dict names, written by scripts/export_pretrained.py. Checkpoints of whole models are read
// by the pipeline library (pipeline/checkpoint.hpp, pipeline/reference_import.hpp).

#include <filesystem>

namespace th::model {

class EncoderImpl;

// Throws th::Error naming a missing or mis-shaped key.
void load_pretrained_encoder(EncoderImpl& encoder, const std::filesystem::path& npz);

}  // namespace th::model
