// One run's configuration (run.yaml), parsed key by key with errors that name the key.
#include "daemon/run_config.hpp"

#include <cmath>

#include "core/base/errors.hpp"
#include "core/base/yaml_access.hpp"

namespace plenopiv::daemon {
namespace {

// `[min, max]` in mm along one axis of `volume`.
std::array<double, 2> range_mm(const YamlMap& volume, const char* key) {
  const YAML::Node node = volume.node()[key];
  if (!node) volume.fail(key, "missing (expected [min, max] in mm)");
  if (!node.IsSequence() || node.size() != 2) volume.fail(key, "expected [min, max] in mm");
  std::array<double, 2> r{};
  for (int i = 0; i < 2; ++i) {
    try {
      r[i] = node[i].as<double>();
    } catch (const YAML::Exception&) {
      volume.fail(key, "expected numbers [min, max] in mm, got '" + node[i].as<std::string>() + "'");
    }
    if (!std::isfinite(r[i])) volume.fail(key, "expected finite numbers");
  }
  if (!(r[1] > r[0])) volume.fail(key, "max must be greater than min");
  return r;
}

YAML::Node opaque_section(const YamlMap& map, const char* key) {
  if (!map.has(key)) return YAML::Node(YAML::NodeType::Map);
  const YAML::Node node = map.node()[key];
  if (!node.IsMap()) map.fail(key, "expected a mapping of settings");
  return node;
}

}  // namespace

Grid3 RunConfig::volume_grid() const {
  Grid3 g;
  for (int a = 0; a < 3; ++a) {
    g.shape[a] = int(std::floor((volume_max_mm[a] - volume_min_mm[a]) / voxel_mm + 1e-9)) + 1;
    g.origin_mm[a] = volume_min_mm[a];
    g.spacing_mm[a] = voxel_mm;
  }
  return g;
}

std::string RunConfig::process_yaml() const {
  const Grid3 g = volume_grid();
  YAML::Node root(YAML::NodeType::Map);
  root["dt_s"] = dt_s;
  YAML::Node volume(YAML::NodeType::Map);
  const char* axes[3] = {"x_mm", "y_mm", "z_mm"};
  for (int a = 0; a < 3; ++a) {
    // Half a voxel beyond the first and last centres: grid_for_extent gives back volume_grid().
    const double half = 0.5 * g.spacing_mm[a];
    YAML::Node range(YAML::NodeType::Sequence);
    range.push_back(g.origin_mm[a] - half);
    range.push_back(g.origin_mm[a] + (g.shape[a] - 1) * g.spacing_mm[a] + half);
    range.SetStyle(YAML::EmitterStyle::Flow);
    volume[axes[a]] = range;
  }
  volume["voxel_mm"] = voxel_mm;
  if (depth_guard_mm) volume["depth_guard_mm"] = *depth_guard_mm;
  root["volume"] = volume;
  if (reconstruction.size() > 0) root["reconstruction"] = YAML::Clone(reconstruction);
  if (correlation.size() > 0) root["correlation"] = YAML::Clone(correlation);
  YAML::Emitter out;
  out.SetDoublePrecision(17);
  out << root;
  return "# Processing settings of this run, resolved from run.yaml (core/process schema:\n"
         "# `plenopiv process --config`, `plenopiv process --run`).\n" +
         std::string(out.c_str()) + "\n";
}

RunConfig parse_run_config(const std::string& text, const std::string& source) {
  const YAML::Node root = load_yaml_text(text, source);
  if (!root.IsMap()) throw InputError(source + ": expected a mapping of run settings");
  const YamlMap map(root, source);
  map.reject_unknown({"camera_uri", "trigger_uri", "pairs", "duration_s", "rate_hz", "dt_s",
                      "volume", "reconstruction", "correlation", "publish_volumes",
                      "max_pairs_in_flight", "live_queue"});
  RunConfig c;
  c.text = text;
  c.camera_uri = map.string_or("camera_uri", "");
  c.trigger_uri = map.string_or("trigger_uri", "");
  const long long pairs = map.integer_or("pairs", 0);
  if (pairs < 0) map.fail("pairs", "must be >= 0 (0: until stopped), got " + std::to_string(pairs));
  c.pair_count = std::uint64_t(pairs);
  c.duration_s = map.number_or("duration_s", 0.0);
  if (!(c.duration_s >= 0) || !std::isfinite(c.duration_s)) map.fail("duration_s", "must be >= 0 s (0: until stopped)");
  c.rate_hz = map.number_or("rate_hz", c.rate_hz);
  if (!(c.rate_hz > 0) || c.rate_hz > 1000) map.fail("rate_hz", "must be in (0, 1000] Hz");
  c.dt_s = map.number_or("dt_s", c.dt_s);
  if (!(c.dt_s > 0) || c.dt_s >= 1.0 / c.rate_hz) {
    map.fail("dt_s", "must be > 0 s and shorter than one repetition period (1/rate_hz)");
  }

  const YamlMap volume = map.map("volume");
  volume.reject_unknown({"x_mm", "y_mm", "z_mm", "voxel_mm", "depth_guard_mm"});
  const char* axes[3] = {"x_mm", "y_mm", "z_mm"};
  for (int a = 0; a < 3; ++a) {
    const auto r = range_mm(volume, axes[a]);
    c.volume_min_mm[a] = r[0];
    c.volume_max_mm[a] = r[1];
  }
  c.voxel_mm = volume.number("voxel_mm");
  if (!(c.voxel_mm > 0)) volume.fail("voxel_mm", "must be > 0 mm");
  if (volume.has("depth_guard_mm")) {
    c.depth_guard_mm = volume.number("depth_guard_mm");
    if (!(*c.depth_guard_mm >= 0)) volume.fail("depth_guard_mm", "must be >= 0 mm");
  }
  const Grid3 g = c.volume_grid();
  if (double(g.count()) > 512.0 * 1024 * 1024) {
    volume.fail("voxel_mm", "the volume would have " + std::to_string(g.count()) +
                                " voxels; more than 2^29 does not fit a live run");
  }

  c.reconstruction = opaque_section(map, "reconstruction");
  c.correlation = opaque_section(map, "correlation");
  c.publish_volumes = map.boolean_or("publish_volumes", false);
  c.max_pairs_in_flight = map.integer_in("max_pairs_in_flight", c.max_pairs_in_flight, 1, 64);
  c.live_queue = map.integer_in("live_queue", c.live_queue, 1, 64);
  return c;
}

}  // namespace plenopiv::daemon
