// One frame pair to a vector field: the run config (volume, MART, correlation, dt) and the
// composition reconstruct A, reconstruct B, correlate, shared by `plenopiv process` and live mode.
#pragma once

#include <array>
#include <functional>
#include <string>

#include "core/base/grid.hpp"
#include "core/base/image.hpp"
#include "core/base/yaml_access.hpp"
#include "core/piv/multipass.hpp"
#include "core/piv/settings.hpp"
#include "core/recon/mart.hpp"
#include "core/recon/weights.hpp"

namespace plenopiv::process {

// Everything one pair needs besides the camera and calibration. Defaults: the paper's MART (mu
// 0.5, 5 iterations) and core/piv's default correlation (piv::CorrelationSettings).
struct ProcessSettings {
  Grid3 grid;                        // the volume the user asked for, mm: correlated and returned
  // Slices reconstructed beyond each depth end of `grid` and then dropped. A particle just outside
  // the box puts its elongated image (about ±1 mm at 4 mm from focus on the sec 5.4 camera) into
  // the end slices, where it stays from frame to frame and pulls the correlation's depth peak
  // towards zero: on a 0.25 mm depth shift measured 0.12 mm without a guard and 0.20 mm with
  // 1 mm (docs/benchmarks.md, "Depth displacement").
  double depth_guard_mm = 1.0;
  // (u, v) samples per aperture axis relative to sec 5.2's count (recon::WeightingOperator).
  double angular_sampling = 1.0;
  recon::MartSettings mart;
  piv::CorrelationSettings correlation;  // dt_s lives here

  int guard_slices() const;           // depth_guard_mm in whole slices (rounded up)
  Grid3 reconstruction_grid() const;  // `grid` with the guard slices at both depth ends
};

// The box of voxels centred on [lo, hi] per axis with `voxel_mm` spacing (x, y, z); InputError
// naming `where` when a size is not positive, an axis has min >= max, or the count is absurd.
Grid3 grid_for_extent(const std::array<double, 3>& lo, const std::array<double, 3>& hi,
                      const std::array<double, 3>& voxel_mm, const std::string& where);

// Reads a run config mapping (systemd/config/process.yaml):
//   dt_s: 0.0001                                   (required)
//   volume: {x_mm: [a, b], y_mm: [..], z_mm: [..], voxel_mm: 0.125, voxel_z_mm: 0.125, depth_guard_mm: 1}
//   reconstruction: {iterations, mu, start: mlos|ones, noise_threshold, dark_weight_cutoff, convergence,
//                    angular_sampling}
//   correlation: {passes, median, signal_threshold}    (as piv::load_correlation_settings)
// Unknown keys are refused; every value is checked; InputError names the file and key.
ProcessSettings process_settings_from(const YamlMap& root);
ProcessSettings load_process_settings(const std::filesystem::path& path);

// The weighting operator process_pair needs for these settings: built on reconstruction_grid()
// (the guard slices included) with the settings' angular sampling.
recon::WeightingOperator make_operator(const optics::CameraModel& camera, const optics::MicrolensArray& lenses,
                                       ImageF white, const ProcessSettings& settings);

// Where the time went and what was skipped.
struct StageTimes {
  double reconstruct_a_s = 0, reconstruct_b_s = 0, correlate_s = 0;
};

struct PairResult {
  Volume volume_a, volume_b;
  recon::SkipReport skipped_a, skipped_b;
  piv::CorrelationResult correlation;
  StageTimes times;
};

// Progress: stage name ("reconstruct A", "reconstruct B", "correlate") and the fraction of the
// whole pair done, in [0, 1].
using PairProgress = std::function<void(const std::string& stage, double fraction)>;

// Reconstructs both frames with `op` (whose grid must be settings.reconstruction_grid():
// InputError otherwise), drops the guard slices, then correlates them (PairResult's volumes are on
// settings.grid). Images are validated (sensor-sized, finite, non-negative) and named
// "frame A" / "frame B" in errors. Bit-identical at any thread count.
PairResult process_pair(const recon::WeightingOperator& op, const ImageF& frame_a, const ImageF& frame_b,
                        const ProcessSettings& settings, const PairProgress& progress = {});

}  // namespace plenopiv::process
