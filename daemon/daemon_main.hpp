// plenopivd's main loop as a function, so test builds can add a test camera and processing stage.
#pragma once

#include "daemon/run.hpp"

namespace plenopiv::daemon {

// What a particular plenopivd build brings beyond the registered drivers.
struct DaemonExtensions {
  ProcessFactory processing;       // empty: runs record raw frames only
  std::string processing_summary;  // shown in status ("MART + 3D FFT correlation", ...)
};

// Parses the command line, serves control requests and runs until SIGTERM/SIGINT; returns the
// exit status (0 clean, 1 internal error, 2 bad input).
int daemon_main(int argc, char** argv, const DaemonExtensions& extensions);

}  // namespace plenopiv::daemon
