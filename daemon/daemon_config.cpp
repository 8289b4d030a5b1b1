// plenopivd's own configuration (plenopivd.yaml): endpoints, data directory, devices, logging.
#include "daemon/daemon_config.hpp"

#include "core/base/errors.hpp"
#include "core/base/yaml_access.hpp"

namespace plenopiv::daemon {
namespace {

bool is_local(const std::string& endpoint) {
  for (const char* prefix : {"ipc://", "inproc://", "tcp://127.0.0.1:", "tcp://localhost:",
                             "tcp://[::1]:"}) {
    if (endpoint.rfind(prefix, 0) == 0) return true;
  }
  return false;
}

bool is_endpoint(const std::string& endpoint) {
  for (const char* prefix : {"ipc://", "inproc://", "tcp://"}) {
    if (endpoint.rfind(prefix, 0) == 0 && endpoint.size() > std::string(prefix).size()) return true;
  }
  return false;
}

}  // namespace

DaemonConfig load_daemon_config(const std::filesystem::path& path) {
  const YamlMap map(load_yaml_file(path), path.string());
  map.reject_unknown({"control_endpoint", "publish_endpoint", "data_dir", "camera_file",
                      "camera_uri", "trigger_uri", "log_level", "publish_high_water_mark"});
  DaemonConfig config;
  const std::filesystem::path base = path.parent_path();
  auto resolve = [&](const std::string& p) {
    const std::filesystem::path fp(p);
    return fp.is_absolute() ? fp : base / fp;
  };
  config.control_endpoint = map.string_or("control_endpoint", config.control_endpoint);
  config.publish_endpoint = map.string_or("publish_endpoint", config.publish_endpoint);
  if (map.has("data_dir")) config.data_dir = resolve(map.string("data_dir"));
  if (map.has("camera_file")) config.camera_file = resolve(map.string("camera_file"));
  config.camera_uri = map.string_or("camera_uri", config.camera_uri);
  config.trigger_uri = map.string_or("trigger_uri", config.trigger_uri);
  config.log_level = map.choice_or("log_level", {"trace", "debug", "info", "warn", "error"},
                                   config.log_level);
  const long long hwm = map.integer_or("publish_high_water_mark", config.publish_high_water_mark);
  if (hwm < 1 || hwm > 1000) {
    map.fail("publish_high_water_mark", "must be between 1 and 1000 messages, got " + std::to_string(hwm));
  }
  config.publish_high_water_mark = int(hwm);
  validate(config, path.string());
  return config;
}

void validate(const DaemonConfig& config, const std::string& source) {
  if (!is_endpoint(config.control_endpoint)) {
    throw InputError(source + ": control_endpoint: '" + config.control_endpoint +
                     "' is not a ZeroMQ endpoint (tcp://host:port or ipc://path)");
  }
  if (!is_local(config.control_endpoint)) {
    throw InputError(source + ": control_endpoint: '" + config.control_endpoint +
                     "' is reachable from other machines; control stays on 127.0.0.1 unless "
                     "CURVE keys are configured, which this version does not support");
  }
  if (!is_endpoint(config.publish_endpoint)) {
    throw InputError(source + ": publish_endpoint: '" + config.publish_endpoint +
                     "' is not a ZeroMQ endpoint (tcp://host:port or ipc://path)");
  }
}

}  // namespace plenopiv::daemon
