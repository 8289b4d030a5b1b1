// One run's configuration (run.yaml), parsed key by key with errors that name the key.
#include "daemon/run_config.hpp"

#include <cmath>
#include <span>
#include <string_view>
#include <vector>

#include "core/base/errors.hpp"
#include "core/base/yaml_access.hpp"

namespace plenopiv::daemon {

std::string RunConfig::process_yaml() const {
  return process::spec_text(processing,
                            "Processing settings of this run, as its run.yaml gave them (core/process schema:\n"
                            "`plenopiv process --config`, `plenopiv process --run`).");
}

RunConfig parse_run_config(const std::string& text, const std::string& source) {
  const YAML::Node root = load_yaml_text(text, source);
  const YamlMap map(root, source);
  std::vector<std::string_view> known{"camera_uri",      "trigger_uri",         "pairs",     "duration_s", "rate_hz",
                                      "publish_volumes", "max_pairs_in_flight", "live_queue"};
  known.insert(known.end(), std::begin(process::kProcessKeys), std::end(process::kProcessKeys));
  map.reject_unknown(std::span<const std::string_view>(known));
  RunConfig c;
  c.text = text;
  c.camera_uri = map.string_or("camera_uri", "");
  c.trigger_uri = map.string_or("trigger_uri", "");
  const long long pairs = map.integer_or("pairs", 0);
  if (pairs < 0) map.fail("pairs", "must be >= 0 (0: until stopped), got " + std::to_string(pairs));
  c.pair_count = std::uint64_t(pairs);
  c.duration_s = map.number_or("duration_s", 0.0);
  if (!(c.duration_s >= 0) || !std::isfinite(c.duration_s)) map.fail("duration_s", "must be >= 0 s (0: until stopped)");
  // The range the laser allows is the trigger sequencer's to check (with the rig's limits); this
  // only keeps the number sane.
  c.rate_hz = map.number_or("rate_hz", c.rate_hz);
  if (!(c.rate_hz > 0) || c.rate_hz > 1000) map.fail("rate_hz", "must be in (0, 1000] Hz");

  c.processing = process::processing_part(root);
  c.spec = process::process_spec_from(YamlMap(c.processing, source));
  c.dt_s = c.spec.full.correlation.dt_s;
  if (double(c.spec.full.reconstruction_grid().count()) > 512.0 * 1024 * 1024) {
    map.fail("volume", "the volume would have " + std::to_string(c.spec.full.reconstruction_grid().count()) +
                           " voxels; more than 2^29 does not fit a live run");
  }

  c.publish_volumes = map.boolean_or("publish_volumes", false);
  c.max_pairs_in_flight = map.integer_in("max_pairs_in_flight", c.max_pairs_in_flight, 1, 64);
  c.live_queue = map.integer_in("live_queue", c.live_queue, 1, 64);
  return c;
}

}  // namespace plenopiv::daemon
