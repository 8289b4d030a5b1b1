// plenopivd's main loop as a function, so test builds can add a test camera and processing stage.
#pragma once

#include "daemon/run.hpp"

namespace plenopiv::daemon {

// What a particular plenopivd build brings beyond the registered drivers.
struct DaemonExtensions {
  // Empty: plenoptic_processing() on the configured camera_file (none without one: runs then
  // record raw frames only).
  ProcessFactory processing;
  std::string processing_summary;  // shown in status ("MART + 3D FFT correlation", ...)
};

// Parses the command line, serves control requests and runs until SIGTERM/SIGINT; returns the
// exit status (0 clean, 1 internal error, 2 bad input).
int daemon_main(int argc, char** argv, const DaemonExtensions& extensions);

}  // namespace plenopiv::daemon
