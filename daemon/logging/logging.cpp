// spdlog set up once per program: the console, or the systemd journal when run by systemd.
#include "daemon/logging/logging.hpp"

#include <spdlog/sinks/stdout_color_sinks.h>
#include <spdlog/sinks/systemd_sink.h>
#include <spdlog/spdlog.h>

#include <cstdlib>

#include "core/base/errors.hpp"

namespace plenopiv {

void setup_logging(const std::string& program, const std::string& level, LogTarget target) {
  const spdlog::level::level_enum parsed = spdlog::level::from_str(level);
  if (parsed == spdlog::level::off && level != "off") {
    throw InputError("log level '" + level + "' is not one of trace, debug, info, warn, error, off");
  }
  if (target == LogTarget::automatic) {
    target = std::getenv("JOURNAL_STREAM") ? LogTarget::journal : LogTarget::console;
  }
  std::shared_ptr<spdlog::logger> logger;
  if (target == LogTarget::journal) {
    // The journal keeps its own time stamps and levels: the sink maps levels to priorities.
    logger = std::make_shared<spdlog::logger>(program, std::make_shared<spdlog::sinks::systemd_sink_mt>(program));
    logger->set_pattern("%v");
  } else {
    logger = std::make_shared<spdlog::logger>(program, std::make_shared<spdlog::sinks::stderr_color_sink_mt>());
    logger->set_pattern("%Y-%m-%d %H:%M:%S.%e %^%-5l%$ [%n] %v");
  }
  logger->set_level(parsed);
  spdlog::set_default_logger(logger);
}

}  // namespace plenopiv
