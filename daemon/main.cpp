// plenopivd: the plenopiv daemon — serves control requests, runs acquisitions, publishes results.
#include "daemon/daemon_main.hpp"

int main(int argc, char** argv) {
  // Processing: MART and 3D correlation on the configured camera file (daemon/processing.hpp).
  return plenopiv::daemon::daemon_main(argc, argv, {});
}
