#pragma once
// .npy and .npz files as numpy writes them (METHOD 1.4).
//
// Numeric arrays map to tensors of the matching dtype: f4->Float, f8->Double, i4->Int,
// i8->Long, u1->Byte, b1->Bool, also f2->Half, i1->Char, i2->Short and, widened, u2->Int and
// u4->Long (little and big endian; C and Fortran order, always returned C-contiguous). Object
// arrays ('|O', e.g. ZJU-MoCap's annots.npy, a dict saved with np.save) hold a pickle and are
// read through read_npy_value.

#include <torch/types.h>

#include <filesystem>
#include <map>
#include <string>

#include "io/pickle.hpp"

namespace th::io {

// A numeric .npy file (format 1.0, 2.0 or 3.0). Throws th::Error naming the file for anything
// malformed, an object array, an unsupported dtype or a shape whose byte count does not match
// the file size.
torch::Tensor read_npy(const std::filesystem::path& path);
// The same from bytes already in memory; `name` is used in error messages.
torch::Tensor parse_npy(const std::string& bytes, const std::string& name);

// Any .npy: numeric arrays come back as Value::array; object arrays are unpickled (a 0-d
// object array, as np.save writes a dict, comes back as the object itself).
Value read_npy_value(const std::filesystem::path& path);
Value parse_npy_value(const std::string& bytes, const std::string& name);

// Writes a numeric tensor (any supported dtype, any strides) as version 1.0, C order, little
// endian, byte-identical to np.save. Written atomically (temporary file + rename).
void write_npy(const std::filesystem::path& path, const torch::Tensor& array);
std::string npy_bytes(const torch::Tensor& array);

// Writes a Python object as np.save(path, obj, allow_pickle=True) does for a non-array object:
// a 0-d object array whose data is a protocol-3 pickle. Byte-identical to numpy's output for
// the subset Value holds (see pickle_bytes for how strings are shared). An Array value is
// written as write_npy does. Atomic.
void write_npy_value(const std::filesystem::path& path, const Value& object);
std::string npy_value_bytes(const Value& object);

// .npz archives (np.savez, stored, and np.savez_compressed, deflate). Keys without ".npy".
std::map<std::string, torch::Tensor> read_npz(const std::filesystem::path& path);
std::map<std::string, torch::Tensor> parse_npz(const std::string& bytes, const std::string& name);
// Writes like np.savez (stored, no compression; members "<key>.npy"). Atomic.
void write_npz(const std::filesystem::path& path,
               const std::map<std::string, torch::Tensor>& arrays);
std::string npz_bytes(const std::map<std::string, torch::Tensor>& arrays);

}  // namespace th::io
