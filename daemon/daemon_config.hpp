// plenopivd's own configuration (plenopivd.yaml): endpoints, data directory, devices, logging.
#pragma once

#include <filesystem>
#include <optional>
#include <string>
#include <string_view>

#include "drivers/trigger/trigger.hpp"

namespace plenopiv::daemon {

// The rig's timing (plenopivd.yaml `timing:`): what the laser and camera need and allow. Each
// run brings its own rate_hz and dt_s.
struct RigTiming {
  drivers::TimingRequest request;  // repetition_rate_hz and pulse_separation_s unused: per run
  drivers::TimingLimits limits;
  double gate_width_s = 10e-6;  // hardware-timed mode: the delay generator's trigger pulse
};

// The schedule a run plays on `trigger`: the full sequence (both cavities and the camera) at
// `rate_hz` with `dt_s`; when the trigger wires `gate` and no Q-switch line, hardware-timed mode
// (one gate pulse per shot; the delay generator makes dt). InputError naming what to change.
drivers::Schedule run_schedule(const RigTiming& timing, const drivers::TriggerInfo& trigger, double rate_hz,
                               double dt_s);

// CURVE authentication (plenopivd.yaml `curve:`; `plenopiv keys` makes the certificate files).
struct CurveConfig {
  std::filesystem::path server_certificate;  // the daemon's .key_secret file
  std::filesystem::path authorized_clients;  // a folder of the admitted clients' *.key files
  bool publish = false;                      // subscribers need an admitted key too
};

struct DaemonConfig {
  // Local by default: an ipc:// socket file that only the daemon's user and control_socket_group
  // can open. tcp:// needs `curve:` (any host, local ones included).
  std::string control_endpoint = "ipc:///run/plenopiv/control";
  std::string control_socket_group;  // ipc:// only: the group allowed to connect (e.g. plenopiv)
  std::optional<CurveConfig> curve;
  std::string publish_endpoint = "tcp://127.0.0.1:5556";  // read-only data; binds wider when configured
  // Whether the simulated camera (sim://) exists in this daemon. Off by default: a rig's daemon
  // opens real devices only; the demo, tests and development turn it on.
  bool simulation = false;
  // The only folder the replay camera (replay://<folder>, drivers/replay/replay_camera.hpp) may
  // read: replay URIs name folders under it. Needs simulation; empty (default): no replay camera.
  std::filesystem::path replay_dir;
  std::filesystem::path data_dir = "/var/lib/plenopiv";
  std::filesystem::path camera_file;  // empty: the camera driver reports its own
  // The rig's calibration file (HDF5 from `plenopiv calibrate`, made for camera_file); empty: the
  // nominal lattice and geometric white image. Checked at start and at every run start.
  std::filesystem::path calibration_file;
  std::string camera_uri;  // the default camera of runs that name none; empty: each run names its own
  std::string trigger_uri = "sim://";
  std::string log_level = "info";
  int publish_high_water_mark = 4;  // messages queued per subscriber before they are dropped
  // The niceness (0-19) of the threads that process pairs (both lanes, the alignment preview):
  // above the recording's, so that a busy pipeline takes the cores the recording leaves and never
  // makes the camera's queue overflow. 0: processing competes with recording as an equal.
  int processing_nice = 10;
  RigTiming timing;
};

// The folder in data_dir where runs' depth responses are kept (plenoptic_processing), beside the
// run folders (run-...) and calibration images (calibration-...).
inline constexpr std::string_view kResponseCacheFolder = "depth-responses";

// Reads plenopivd.yaml; relative paths are taken from the file's folder. Every bad key is an
// InputError naming it. The control endpoint is an ipc:// socket unless `curve:` is configured.
DaemonConfig load_daemon_config(const std::filesystem::path& path);
// Checks a config however it was assembled (file and command-line overrides).
void validate(const DaemonConfig& config, const std::string& source);

}  // namespace plenopiv::daemon
