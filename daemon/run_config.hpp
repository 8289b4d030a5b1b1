// One run's configuration (run.yaml): devices, how many pairs at which rate, the volume, and the
// processing settings handed on unread to the processing stage.
#pragma once

#include <yaml-cpp/yaml.h>

#include <array>
#include <optional>
#include <string>

#include "core/base/grid.hpp"

namespace plenopiv::daemon {

struct RunConfig {
  std::string text;         // the YAML as the operator wrote it (saved in the run folder)
  std::string camera_uri;   // empty: the daemon's default
  std::string trigger_uri;  // empty: the daemon's default
  std::uint64_t pair_count = 0;  // 0: until stopped or duration_s
  double duration_s = 0.0;       // 0: until stopped or pair_count
  double rate_hz = 1.0;          // laser repetition rate: pairs per second
  double dt_s = 100e-6;          // pulse separation
  std::array<double, 3> volume_min_mm{0, 0, 0}, volume_max_mm{0, 0, 0};  // x, y, z
  double voxel_mm = 0.0;
  std::optional<double> depth_guard_mm;  // volume.depth_guard_mm; unset: core/process's default
  YAML::Node reconstruction;  // opaque to the daemon: core/recon reads it
  YAML::Node correlation;     // opaque to the daemon: core/piv reads it
  bool publish_volumes = false;
  int max_pairs_in_flight = 2;  // bounded work in the processing stage
  // Recorded pairs waiting for the live path, at most (the newest are kept, older ones dropped
  // from processing and counted; they stay on disk). 1..64, default 2.
  int live_queue = 2;

  // The reconstruction grid: voxel centres from volume_min_mm in steps of voxel_mm, covering max.
  Grid3 volume_grid() const;
  // The processing settings as core/process reads them (process::process_settings_from, the
  // schema of systemd/config/process.yaml): dt_s, the volume as the extent whose voxel centres are
  // volume_grid() (exactly for binary fractions such as 0.125 mm, else to rounding), the run's
  // volume.depth_guard_mm when set, and the reconstruction and correlation sections as given. The live
  // stage parses this text and the run folder keeps it (process.yaml), so `plenopiv process --run`
  // reprocesses with exactly the live settings.
  std::string process_yaml() const;
};

// Parses run.yaml text; `source` names it in messages ("run.yaml", "start request"). Every bad or
// unknown key is an InputError naming it.
RunConfig parse_run_config(const std::string& text, const std::string& source);

}  // namespace plenopiv::daemon
