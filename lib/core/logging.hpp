#pragma once
// Logging: spdlog to the console and, once a run directory exists, to <run>/log.txt.

#include <filesystem>

namespace th::logging {

// Console logger as the default spdlog logger ("info", or "debug" when verbose).
void init_console(bool verbose = false);
// Adds a file sink (<dir>/log.txt, appended) to the default logger.
void add_file_sink(const std::filesystem::path& file);

}  // namespace th::logging
