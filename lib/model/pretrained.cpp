#include "model/pretrained.hpp"

#include "io/npy.hpp"
#include "model/encoder.hpp"

namespace th::model {

void load_pretrained_encoder(EncoderImpl& encoder, const std::filesystem::path& npz) {
  encoder.load_resnet_state(io::read_npz(npz), npz.string());
}

}  // namespace th::model
