#pragma once
// Human3.6M as preprocessed by Animatable NeRF (METHOD 1.3): subjects S1, S5, S6, S7, S8, S9, S11
// with 4 cameras, each in <root>/<S>/Posing/ with the ZJU-MoCap layout (annots.npy, images,
// mask_cihp/, new_params/, new_vertices/). It is read by the ZJU-MoCap reader; only the folder
// of a subject differs.

#include <filesystem>
#include <string>

#include "core/config.hpp"

namespace th::data {

// The folder of one person by data.dataset: <root>/<name>/Posing for h36m, <root>/<name> for
// zju_mocap and synthetic. A layout that does not match the named dataset fails naming the
// folder it expected and the key to change.
std::filesystem::path human_folder(const std::filesystem::path& root, const std::string& name,
                                   DatasetKind dataset);

}  // namespace th::data
