#pragma once
// Whole files in and out, safely: what every library that writes results, checkpoints or pages
// uses (part of lib/io's public API).

#include <filesystem>
#include <string>
#include <string_view>

namespace th::io {

// The whole file; throws th::Error naming the path when it cannot be read.
std::string read_file(const std::filesystem::path& path);
// Writes through a temporary file in the same folder and renames it over `path`, so readers
// never see a half-written file. Throws th::Error naming the path.
void write_file_atomic(const std::filesystem::path& path, std::string_view bytes);

}  // namespace th::io
