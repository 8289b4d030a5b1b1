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

std::string QualityLane::policy() const {
  switch (take) {
    case Take::off:
      return "off";
    case Take::newest:
      return "newest";
    case Take::every:
      return "every " + std::to_string(every);
  }
  return "?";
}

namespace {

// `quality: off | newest | {every: N}` and `quality_queue`, against the spec's tiers.
QualityLane parse_quality_lane(const YamlMap& map, const process::ProcessSpec& spec) {
  QualityLane q;
  q.take = spec.live ? QualityLane::Take::newest : QualityLane::Take::off;
  if (map.has("quality")) {
    if (map.node()["quality"].IsMap()) {
      const YamlMap every = map.map("quality");
      every.reject_unknown({"every"});
      const long long n = every.integer("every");
      if (n < 1 || n > (1ll << 31))
        every.fail("every", "must be in [1, 2^31] (1: every pair), got " + std::to_string(n));
      q.take = QualityLane::Take::every;
      q.every = std::uint64_t(n);
    } else {
      q.take = map.choice("quality", {"off", "newest"}) == "off" ? QualityLane::Take::off : QualityLane::Take::newest;
    }
    if (q.on() && !spec.live) {
      map.fail("quality",
               "a quality lane needs a live: tier in the processing settings (without one the live lane already "
               "runs the full settings); add a live: section or leave quality out");
    }
  }
  q.queue = map.integer_in("quality_queue", q.queue, 1, 64);
  return q;
}

drivers::Roi parse_camera_roi(const YamlMap& map) {
  drivers::Roi r;
  const auto roi = map.optional_map("camera_roi");
  if (!roi) return r;
  roi->reject_unknown({"x", "y", "width", "height"});
  for (const char* size : {"width", "height"}) {
    if (!roi->has(size)) roi->fail(size, "is required: the region's size in pixels");
  }
  constexpr int kMaxPx = 1 << 16;
  r.x = roi->integer_in("x", 0, 0, kMaxPx);
  r.y = roi->integer_in("y", 0, 0, kMaxPx);
  r.width = roi->integer_in("width", 0, 1, kMaxPx);
  r.height = roi->integer_in("height", 0, 1, kMaxPx);
  return r;
}

PreviewSettings parse_preview(const YamlMap& map) {
  PreviewSettings p;
  const auto preview = map.optional_map("preview");
  if (!preview) return p;
  preview->reject_unknown({"interval_s", "downsample", "z_mm"});
  p.interval_s = preview->number_or("interval_s", 1.0);
  if (!(p.interval_s >= 0.1 && p.interval_s <= 3600)) preview->fail("interval_s", "must be in [0.1, 3600] s");
  p.downsample = preview->integer_in("downsample", p.downsample, 1, 64);
  p.z_mm = preview->number_or("z_mm", p.z_mm);
  if (!(std::abs(p.z_mm) <= 1000)) preview->fail("z_mm", "must be in [-1000, 1000] mm");
  return p;
}

}  // namespace

RunConfig parse_run_config(const std::string& text, const std::string& source) {
  const YAML::Node root = load_yaml_text(text, source);
  const YamlMap map(root, source);
  std::vector<std::string_view> known{
      "camera_uri",      "trigger_uri",         "pairs",      "duration_s", "rate_hz",
      "publish_volumes", "max_pairs_in_flight", "live_queue", "quality",    "quality_queue",
      "preview",         "camera_outage_s",     "camera_roi"};
  known.insert(known.end(), std::begin(process::kProcessKeys), std::end(process::kProcessKeys));
  map.reject_unknown(std::span<const std::string_view>(known));
  RunConfig c;
  c.text = text;
  c.camera_uri = map.string_or("camera_uri", "");
  c.trigger_uri = map.string_or("trigger_uri", "");
  c.camera_roi = parse_camera_roi(map);
  const long long pairs = map.integer_or("pairs", 0);
  if (pairs < 0) map.fail("pairs", "must be >= 0 (0: until stopped), got " + std::to_string(pairs));
  c.pair_count = std::uint64_t(pairs);
  c.duration_s = map.number_or("duration_s", 0.0);
  if (!(c.duration_s >= 0) || !std::isfinite(c.duration_s)) map.fail("duration_s", "must be >= 0 s (0: until stopped)");
  // The range the laser allows is the trigger sequencer's to check (with the rig's limits); this
  // only keeps the number sane.
  c.camera_outage_s = map.number_or("camera_outage_s", c.camera_outage_s);
  if (!(c.camera_outage_s >= 0) || c.camera_outage_s > 3600) {
    map.fail("camera_outage_s", "must be in [0, 3600] s (0: a lost camera fails the run at once)");
  }
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
  c.quality = parse_quality_lane(map, c.spec);
  c.preview = parse_preview(map);
  return c;
}

}  // namespace plenopiv::daemon
