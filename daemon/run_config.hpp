// One run's configuration (run.yaml): devices, how many pairs at which rate, and the processing
// spec, which core/process parses (the same keys, the same meaning as process.yaml).
#pragma once

#include <yaml-cpp/yaml.h>

#include <cstdint>
#include <string>

#include "core/base/grid.hpp"
#include "core/process/process.hpp"

namespace plenopiv::daemon {

struct RunConfig {
  std::string text;              // the YAML as the operator wrote it (saved in the run folder)
  std::string camera_uri;        // empty: the daemon's default
  std::string trigger_uri;       // empty: the daemon's default
  std::uint64_t pair_count = 0;  // 0: until stopped or duration_s
  double duration_s = 0.0;       // 0: until stopped or pair_count
  double rate_hz = 1.0;          // laser repetition rate: pairs per second
  double dt_s = 100e-6;          // pulse separation: the processing spec's dt_s
  bool publish_volumes = false;
  int max_pairs_in_flight = 2;  // bounded work in the processing stage
  // Recorded pairs waiting for the live path, at most (the newest are kept, older ones dropped
  // from processing and counted; they stay on disk). 1..64, default 2.
  int live_queue = 2;
  // The processing keys (process::kProcessKeys) as written, and the spec core/process made of them.
  YAML::Node processing;
  process::ProcessSpec spec;

  // The volume the run's vectors are on (spec.full.grid).
  const Grid3& volume_grid() const { return spec.full.grid; }
  // The processing keys as process.yaml text: what the run folder keeps and what `plenopiv process
  // --run` reads, so that reprocessing reads exactly the live settings.
  std::string process_yaml() const;
};

// Parses run.yaml text; `source` names it in messages ("run.yaml", "start request"). The
// acquisition keys are read here; dt_s, volume, reconstruction, correlation and live by
// process::process_spec_from. Every bad or unknown key is an InputError naming it.
RunConfig parse_run_config(const std::string& text, const std::string& source);

}  // namespace plenopiv::daemon
