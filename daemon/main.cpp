// plenopivd: the plenopiv daemon — serves control requests, runs acquisitions, publishes results.
#include "daemon/daemon_main.hpp"

int main(int argc, char** argv) {
  // The reconstruction and correlation stage plugs in here once core/recon and core/piv exist.
  return plenopiv::daemon::daemon_main(argc, argv, {});
}
