// plenopivd's main loop as a function, so test builds can add a test camera and processing stage.
#pragma once

#include "daemon/daemon.hpp"

namespace plenopiv::daemon {

// Parses the command line, serves control requests and runs until SIGTERM/SIGINT; returns the
// exit status (0 clean, 1 internal error, 2 bad input).
int daemon_main(int argc, char** argv, const DaemonExtensions& extensions);

}  // namespace plenopiv::daemon
