#include "core/logging.hpp"

#include <spdlog/sinks/basic_file_sink.h>
#include <spdlog/sinks/stdout_color_sinks.h>
#include <spdlog/spdlog.h>

#include "core/error.hpp"

namespace th::logging {

void init_console(bool verbose) {
  auto console = std::make_shared<spdlog::sinks::stderr_color_sink_mt>();
  console->set_pattern("[%H:%M:%S] %^%l%$ %v");
  auto logger = std::make_shared<spdlog::logger>("transhuman", console);
  logger->set_level(verbose ? spdlog::level::debug : spdlog::level::info);
  logger->flush_on(spdlog::level::info);
  spdlog::set_default_logger(logger);
}

void add_file_sink(const std::filesystem::path& file) {
  try {
    auto sink = std::make_shared<spdlog::sinks::basic_file_sink_mt>(file.string(), false);
    sink->set_pattern("[%Y-%m-%d %H:%M:%S.%e] %l %v");
    spdlog::default_logger()->sinks().push_back(sink);
  } catch (const spdlog::spdlog_ex& e) {
    fail("cannot open log file '", file.string(), "': ", e.what());
  }
}

void error_to_files(const std::string& message) {
  const auto logger = spdlog::default_logger();
  if (!logger) return;
  const auto& sinks = logger->sinks();
  const spdlog::details::log_msg msg(logger->name(), spdlog::level::err, message);
  for (size_t i = 1; i < sinks.size(); ++i) {  // sinks[0] is the console
    try {
      sinks[i]->log(msg);
      sinks[i]->flush();
    } catch (const spdlog::spdlog_ex&) {  // a full disk must not hide the error itself
    }
  }
}

}  // namespace th::logging
