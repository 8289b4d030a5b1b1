// One run's configuration (run.yaml): devices, how many pairs at which rate, and the processing
// spec, which core/process parses (the same keys, the same meaning as process.yaml).
#pragma once

#include <yaml-cpp/yaml.h>

#include <cstdint>
#include <string>

#include "core/base/grid.hpp"
#include "core/process/process.hpp"
#include "drivers/camera/camera.hpp"

namespace plenopiv::daemon {

// The quality lane: the run's full settings on the pairs it takes, behind the live lane and at a
// lower priority for the cores, as capacity allows. Only a run whose processing spec has a `live:`
// tier has one (without it the live lane already runs the full settings).
struct QualityLane {
  enum class Take {
    off,     // no quality lane
    newest,  // every recorded pair is offered; it takes the newest waiting and drops the older ones
    every,   // pairs whose index is a multiple of `every` are offered, and taken oldest first
  };
  Take take = Take::off;
  std::uint64_t every = 1;  // Take::every: 1..2^31
  // Pairs waiting for the lane, at most: a push into a full queue drops the oldest (counted; it
  // stays on disk). 1..64, default 2.
  int queue = 2;
  // Pairs the quality lane processes at once: one, whose reconstruction uses every core the live
  // lane leaves it; more would only multiply the memory of a full-settings pair.
  static constexpr int kPairsInFlight = 1;

  bool on() const { return take != Take::off; }
  // "off", "newest" or "every N": what status and the log say.
  std::string policy() const;
};

// The alignment preview (run.yaml `preview: {interval_s, downsample, z_mm}`; absent: none): while
// the run acquires, frame A of the newest recorded pair downsampled and refocused at one depth,
// published on topic `preview`, so the operator focuses and aligns without a second program
// fighting the daemon for the camera.
struct PreviewSettings {
  double interval_s = 0;  // seconds between previews, [0.1, 3600]; default 1 when `preview:` is given; 0: none
  int downsample = 8;     // raw preview pixel = downsample x downsample sensor pixels, 1..64
  double z_mm = 0;        // depth of the refocused slice, mm from the nominal focal plane, |z| <= 1000

  bool on() const { return interval_s > 0; }
};

struct RunConfig {
  std::string text;         // the YAML as the operator wrote it (saved in the run folder)
  std::string camera_uri;   // empty: the daemon's default
  std::string trigger_uri;  // empty: the daemon's default
  // run.yaml `camera_roi: {x, y, width, height}`: the sensor region the camera reads out, in pixels
  // from the sensor's top-left corner; absent (all 0): the whole sensor. The camera refuses a region
  // off its sensor, or one it cannot read out (the simulated and replay cameras: any but the whole).
  drivers::Roi camera_roi;
  std::uint64_t pair_count = 0;  // 0: until stopped or duration_s
  double duration_s = 0.0;       // 0: until stopped or pair_count
  double rate_hz = 1.0;          // laser repetition rate: pairs per second
  // How long a run waits for a lost camera (unplugged, power cycled, network down) to come back
  // before it fails naming the camera; meanwhile its triggers are counted lost ("camera lost").
  double camera_outage_s = 30.0;
  double dt_s = 100e-6;  // pulse separation: the processing spec's dt_s
  bool publish_volumes = false;
  int max_pairs_in_flight = 2;  // bounded work in the processing stage
  // Recorded pairs waiting for the live lane, at most (the newest are kept, older ones dropped
  // from processing and counted; they stay on disk). 1..64, default 2.
  int live_queue = 2;
  // run.yaml `quality: off | newest | {every: N}` and `quality_queue: K`. Default: newest when the
  // processing spec has a live tier, else off; asking for one without a live tier is an InputError.
  QualityLane quality;
  PreviewSettings preview;
  // The processing keys (process::kProcessKeys) as written, and the spec core/process made of them.
  YAML::Node processing;
  process::ProcessSpec spec;

  // The volume the run's vectors are on (spec.full.grid).
  const Grid3& volume_grid() const { return spec.full.grid; }
  // The settings the live lane runs: the live tier when the spec has one, else the full settings.
  process::Tier live_lane_tier() const { return spec.live ? process::Tier::live : process::Tier::full; }
  // The processing keys as process.yaml text: what the run folder keeps and what `plenopiv process
  // --run` reads, so that reprocessing reads exactly the live settings.
  std::string process_yaml() const;
};

// Parses run.yaml text; `source` names it in messages ("run.yaml", "start request"). The
// acquisition and lane keys are read here; dt_s, volume, reconstruction, correlation and live by
// process::process_spec_from. Every bad or unknown key is an InputError naming it.
RunConfig parse_run_config(const std::string& text, const std::string& source);

}  // namespace plenopiv::daemon
