// plenopivd's own configuration (plenopivd.yaml): endpoints, data directory, devices, logging.
#include "daemon/daemon_config.hpp"

#include <algorithm>
#include <cmath>
#include <string_view>
#include <vector>

#include "core/base/errors.hpp"
#include "core/base/yaml_access.hpp"

namespace plenopiv::daemon {
namespace {

bool is_ipc(const std::string& endpoint) {
  return endpoint.rfind("ipc://", 0) == 0 || endpoint.rfind("inproc://", 0) == 0;
}

bool is_endpoint(const std::string& endpoint) {
  for (const char* prefix : {"ipc://", "inproc://", "tcp://"}) {
    if (endpoint.rfind(prefix, 0) == 0 && endpoint.size() > std::string(prefix).size()) return true;
  }
  return false;
}

// `timing:` keys, each a time in s or a rate in Hz, all > 0.
RigTiming timing_from(const YamlMap& map) {
  RigTiming t;
  drivers::TimingRequest& r = t.request;
  drivers::TimingLimits& l = t.limits;
  const std::pair<const char*, double*> keys[] = {{"flashlamp_to_qswitch_s", &r.flashlamp_to_qswitch_s},
                                                  {"camera_pretrigger_s", &r.camera_pretrigger_s},
                                                  {"exposure_a_s", &r.exposure_a_s},
                                                  {"flashlamp_pulse_width_s", &r.flashlamp_pulse_width_s},
                                                  {"qswitch_pulse_width_s", &r.qswitch_pulse_width_s},
                                                  {"camera_pulse_width_s", &r.camera_pulse_width_s},
                                                  {"laser_max_rate_hz", &l.laser_max_rate_hz},
                                                  {"min_flashlamp_to_qswitch_s", &l.min_flashlamp_to_qswitch_s},
                                                  {"max_flashlamp_to_qswitch_s", &l.max_flashlamp_to_qswitch_s},
                                                  {"interline_transfer_s", &l.interline_transfer_s},
                                                  {"frame_b_s", &l.frame_b_s},
                                                  {"camera_max_pair_rate_hz", &l.camera_max_pair_rate_hz},
                                                  {"gate_width_s", &t.gate_width_s}};
  std::vector<std::string_view> known;
  for (const auto& key : keys) known.push_back(key.first);
  map.reject_unknown(known);
  for (const auto& [key, value] : keys) {
    *value = map.number_or(key, *value);
    if (!(*value > 0) || !std::isfinite(*value)) map.fail(key, "must be > 0");
  }
  return t;
}

}  // namespace

drivers::Schedule run_schedule(const RigTiming& timing, const drivers::TriggerInfo& trigger, double rate_hz,
                               double dt_s) {
  const auto wired = [&](drivers::TriggerLine line) {
    return std::find(trigger.outputs.begin(), trigger.outputs.end(), line) != trigger.outputs.end();
  };
  if (wired(drivers::TriggerLine::Gate) && !wired(drivers::TriggerLine::QSwitch1)) {
    return drivers::make_gate_schedule(rate_hz, timing.gate_width_s, timing.limits);
  }
  drivers::TimingRequest r = timing.request;
  r.repetition_rate_hz = rate_hz;
  r.pulse_separation_s = dt_s;
  return drivers::make_schedule(r, timing.limits, trigger.timing_uncertainty_s, trigger.backend);
}

DaemonConfig load_daemon_config(const std::filesystem::path& path) {
  const YamlMap map(load_yaml_file(path), path.string());
  map.reject_unknown({"control_endpoint", "control_socket_group", "curve", "publish_endpoint", "simulation",
                      "replay_dir", "data_dir", "camera_file", "calibration_file", "camera_uri", "trigger_uri",
                      "log_level", "publish_high_water_mark", "processing_nice", "timing"});
  DaemonConfig config;
  const std::filesystem::path base = path.parent_path();
  auto resolve = [&](const std::string& p) {
    const std::filesystem::path fp(p);
    return fp.is_absolute() ? fp : base / fp;
  };
  config.control_endpoint = map.string_or("control_endpoint", config.control_endpoint);
  config.control_socket_group = map.string_or("control_socket_group", config.control_socket_group);
  if (auto curve = map.optional_map("curve")) {
    curve->reject_unknown({"server_certificate", "authorized_clients", "publish"});
    CurveConfig c;
    c.server_certificate = resolve(curve->string("server_certificate"));
    c.authorized_clients = resolve(curve->string("authorized_clients"));
    c.publish = curve->boolean_or("publish", false);
    config.curve = c;
  }
  config.publish_endpoint = map.string_or("publish_endpoint", config.publish_endpoint);
  config.simulation = map.boolean_or("simulation", config.simulation);
  if (map.has("replay_dir")) config.replay_dir = resolve(map.string("replay_dir"));
  if (map.has("data_dir")) config.data_dir = resolve(map.string("data_dir"));
  if (map.has("camera_file")) config.camera_file = resolve(map.string("camera_file"));
  if (map.has("calibration_file")) config.calibration_file = resolve(map.string("calibration_file"));
  config.camera_uri = map.string_or("camera_uri", config.camera_uri);
  config.trigger_uri = map.string_or("trigger_uri", config.trigger_uri);
  config.log_level = map.choice_or("log_level", {"trace", "debug", "info", "warn", "error"}, config.log_level);
  config.publish_high_water_mark = map.integer_in("publish_high_water_mark", config.publish_high_water_mark, 1, 1000);
  config.processing_nice = map.integer_in("processing_nice", config.processing_nice, 0, 19);
  if (auto timing = map.optional_map("timing")) config.timing = timing_from(*timing);
  validate(config, path.string());
  return config;
}

void validate(const DaemonConfig& config, const std::string& source) {
  if (!is_endpoint(config.control_endpoint)) {
    throw InputError(source + ": control_endpoint: '" + config.control_endpoint +
                     "' is not a ZeroMQ endpoint (tcp://host:port or ipc://path)");
  }
  if (!is_ipc(config.control_endpoint) && !config.curve) {
    throw InputError(source + ": control_endpoint: '" + config.control_endpoint +
                     "' is a network socket that any user of this machine (or others) could reach: use an "
                     "ipc:// socket (its file permissions admit the daemon's user and control_socket_group), "
                     "or configure curve: (server_certificate, authorized_clients; `plenopiv keys` makes them)");
  }
  if (!config.control_socket_group.empty() && config.control_endpoint.rfind("ipc://", 0) != 0) {
    throw InputError(source + ": control_socket_group: only an ipc:// control_endpoint has a socket file");
  }
  if (!config.simulation && config.camera_uri.rfind("sim://", 0) == 0) {
    throw InputError(source + ": camera_uri: '" + config.camera_uri +
                     "' is the simulated camera, which this daemon does not enable (simulation: true, or "
                     "--simulation)");
  }
  if (!config.simulation && config.camera_uri.rfind("replay://", 0) == 0) {
    throw InputError(source + ": camera_uri: '" + config.camera_uri +
                     "' is the replay camera, which this daemon does not enable (simulation: true, or "
                     "--simulation, and replay_dir)");
  }
  if (!config.simulation && !config.replay_dir.empty()) {
    throw InputError(source + ": replay_dir: '" + config.replay_dir.string() +
                     "' is for the replay camera, a test and bench tool that exists only with simulation: true "
                     "(or --simulation)");
  }
  if (!config.calibration_file.empty() && config.camera_file.empty()) {
    throw InputError(source + ": calibration_file: '" + config.calibration_file.string() +
                     "' needs camera_file, the camera it was made for");
  }
  if (!is_endpoint(config.publish_endpoint)) {
    throw InputError(source + ": publish_endpoint: '" + config.publish_endpoint +
                     "' is not a ZeroMQ endpoint (tcp://host:port or ipc://path)");
  }
}

}  // namespace plenopiv::daemon
