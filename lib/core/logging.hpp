#pragma once
// Logging: spdlog to the console and, once a run directory exists, to <run>/log.txt.

#include <filesystem>
#include <string>

namespace th::logging {

// Console logger as the default spdlog logger ("info", or "debug" when verbose).
void init_console(bool verbose = false);
// Adds a file sink (<dir>/log.txt, appended) to the default logger.
void add_file_sink(const std::filesystem::path& file);
// Writes an error line to the file sinks only (the console already showed it in its own form),
// so that a run's log.txt ends with the reason it stopped.
void error_to_files(const std::string& message);

}  // namespace th::logging
