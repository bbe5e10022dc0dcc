#pragma once
// transhuman-synth's library side: writes a synthetic multi-view human dataset in the exact
// ZJU-MoCap layout (METHOD 1.1) with its body model (METHOD 1.5) and split file (METHOD 1.2);
// with `layout: easymocap`, the same people and pixels in EasyMocap's layout (data/easymocap.hpp:
// intri.yml, extri.yml, images/<camera>/, mask/<camera>/, output/smpl/<frame>.json).
//
// <out>/smpl_model.npz, smpl_model.pkl      the body model (np.savez / SMPL-style pickle)
// <out>/<Human>/annots.npy                  cams {K, R, T (mm), D}, ims [{ims: [paths]}]
// <out>/<Human>/<camera>/<frame>.jpg        images, lens-distorted
// <out>/<Human>/mask{,_cihp}/<camera>/<frame>.png
// <out>/<Human>/new_params/<i>.npy          {poses, Rh, Th, shapes}, with fitting noise
// <out>/<Human>/new_vertices/<i>.npy        (V, 3) float32 world vertices of those params
// <out>/split.yaml, contact_sheet.png, synth_config.yaml (written last: marks completion)
//
// Deterministic: the same config (seed included) gives byte-identical files, whatever the
// number of threads.

#include <yaml-cpp/yaml.h>

#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include "synth/config.hpp"

namespace th::synth {

struct Summary {
  bool skipped = false;  // the folder already held this dataset
  int people = 0, frames = 0, images = 0;
  std::vector<std::string> lines;  // one per person: name, cameras, outfit, motion
  int64_t bytes = 0;
  double seconds = 0.0;
};

// Generates the dataset into `out`. If `out` already holds a finished dataset of the same
// resolved config, nothing is done (skipped); a different config or a non-empty folder that
// is not a finished dataset is refused (th::Error) unless `force`, which replaces it.
Summary generate(const SynthConfig& config, const std::filesystem::path& out, bool force);

// The config as written to <out>/synth_config.yaml (every field).
std::string config_text(const SynthConfig& config);

}  // namespace th::synth
