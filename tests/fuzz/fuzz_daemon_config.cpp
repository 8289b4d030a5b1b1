// Fuzz target: plenopivd.yaml (daemon/daemon_config), read from a file as the daemon reads it, then
// checked as the daemon checks it.
#include "daemon/daemon_config.hpp"
#include "tests/fuzz/fuzz_support.hpp"

using namespace plenopiv;

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const auto path = fuzzing::input_file(data, size, "plenopivd.yaml");
  try {
    const daemon::DaemonConfig config = daemon::load_daemon_config(path);
    daemon::validate(config, path.string());
    fuzzing::require(!config.control_endpoint.empty() && !config.publish_endpoint.empty(),
                     "an accepted daemon config has no endpoint");
    // ipc:// (a socket file) and inproc:// (this process only) are not reachable over a network.
    fuzzing::require(config.control_endpoint.rfind("ipc://", 0) == 0 ||
                         config.control_endpoint.rfind("inproc://", 0) == 0 || config.curve.has_value(),
                     "an accepted daemon config has a tcp:// control endpoint without CURVE");
    fuzzing::require(config.control_endpoint.rfind("tcp://", 0) == 0 ||
                         config.control_endpoint.rfind("ipc://", 0) == 0 ||
                         config.control_endpoint.rfind("inproc://", 0) == 0,
                     "an accepted daemon config has a control endpoint of another transport");
  } catch (const InputError& e) {
    fuzzing::require_names(e, path.string());
  }
  return 0;
}
