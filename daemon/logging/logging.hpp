// spdlog set up once per program: the console, or the systemd journal when run by systemd.
#pragma once

#include <string>

namespace plenopiv {

enum class LogTarget { automatic, console, journal };

// Installs the default logger named `program`. automatic picks the journal when stderr is
// connected to it (systemd sets JOURNAL_STREAM) and the console otherwise. `level` is an spdlog
// level name (trace, debug, info, warn, error); an unknown name is an InputError.
void setup_logging(const std::string& program, const std::string& level = "info",
                   LogTarget target = LogTarget::automatic);

}  // namespace plenopiv
