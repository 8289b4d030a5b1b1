// plenopivd's own configuration (plenopivd.yaml): endpoints, data directory, devices, logging.
#pragma once

#include <filesystem>
#include <string>

namespace plenopiv::daemon {

struct DaemonConfig {
  std::string control_endpoint = "tcp://127.0.0.1:5555";
  std::string publish_endpoint = "tcp://*:5556";
  std::filesystem::path data_dir = "/var/lib/plenopiv";
  std::filesystem::path camera_file;  // empty: the camera driver reports its own
  std::string camera_uri = "sim://?seed=1";
  std::string trigger_uri = "sim://";
  std::string log_level = "info";
  int publish_high_water_mark = 4;    // messages queued per subscriber before they are dropped
};

// Reads plenopivd.yaml; relative paths are taken from the file's folder. Every bad key is an
// InputError naming it. The control endpoint must stay on the local machine (remote control
// needs CURVE keys, which this version does not configure).
DaemonConfig load_daemon_config(const std::filesystem::path& path);
// Checks a config however it was assembled (file and command-line overrides).
void validate(const DaemonConfig& config, const std::string& source);

}  // namespace plenopiv::daemon
