#pragma once
// Human3.6M as preprocessed by Animatable NeRF (SPEC 1.3): subjects S1, S5, S6, S7, S8, S9, S11
// with 4 cameras, each in <root>/<S>/Posing/ with the ZJU-MoCap layout (annots.npy, images,
// mask_cihp/, new_params/, new_vertices/). It is read by the ZJU-MoCap reader; only the folder
// of a subject differs.

#include <filesystem>
#include <string>

namespace th::data {

// <root>/<name>/Posing when it holds an annots.npy (H36M), else <root>/<name> (ZJU-MoCap).
std::filesystem::path human_folder(const std::filesystem::path& root, const std::string& name);

}  // namespace th::data
