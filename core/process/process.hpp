// One frame pair to a vector field: the run config (volume, MART, correlation, dt) and the
// composition reconstruct A, reconstruct B, correlate, shared by `plenopiv process` and live mode.
#pragma once

#include <array>
#include <atomic>
#include <functional>
#include <memory>
#include <string>

#include "core/base/grid.hpp"
#include "core/base/image.hpp"
#include "core/base/yaml_access.hpp"
#include "core/lightfield/lattice_resampling.hpp"
#include "core/optics/camera_model.hpp"
#include "core/optics/microlens_array.hpp"
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
//                    angular_sampling, sensor_blur_sigma_mm, prune, prune_threshold}
//   correlation: {passes, median, signal_threshold}    (as piv::load_correlation_settings)
// Unknown keys are refused; every value is checked; InputError names the file and key.
ProcessSettings process_settings_from(const YamlMap& root);
ProcessSettings load_process_settings(const std::filesystem::path& path);

// Where the time went and what was skipped.
struct StageTimes {
  double reconstruct_a_s = 0, reconstruct_b_s = 0, correlate_s = 0;
};

struct PairResult {
  Volume volume_a, volume_b;
  recon::SkipReport skipped_a, skipped_b;
  piv::CorrelationResult correlation;
  StageTimes times;
  std::string lattice_note;  // PairOperator::note: why and how the frames were resampled; empty if not
};

// Progress: stage name ("reconstruct A", "reconstruct B", "correlate") and the fraction of the
// whole pair done, in [0, 1].
using PairProgress = std::function<void(const std::string& stage, double fraction)>;

// What every pair of a run is reconstructed with; built once per run, shared read-only by
// concurrent pairs. When the separable weights take the lens array (rectangular, centres within
// recon::kSeparableTolerancePx of their column and row means: recon::separable_lattice), the
// operator works on raw pixels. Otherwise (a calibrated array is always rotated a little, warped,
// or hexagonal) the frames are first resampled onto an axis-aligned lattice
// (lightfield::LatticeResampler) and the operator is built on that lattice and its white image;
// `note` then says so and why, e.g. "image resampled onto an axis-aligned lattice: calibrated
// array rotated 0.31 deg, max departure 4.2 px; ...". Throws InputError as WeightingOperator and
// LatticeResampler do.
class PairOperator {
 public:
  // Where the weighting operator comes from, given the lenses and white image it works on (the
  // calibrated ones, or the axis-aligned lattice's): built, or read from a cache
  // (operator_cache.hpp). Empty: built.
  using WeightsSource = std::function<std::unique_ptr<const recon::WeightingOperator>(
      const optics::CameraModel& camera, const optics::MicrolensArray& lenses, const ImageF& white,
      const Grid3& grid, double angular_sampling)>;

  // `grid` and `angular_sampling` as recon::WeightingOperator takes them.
  PairOperator(const optics::CameraModel& camera, const optics::MicrolensArray& lenses, const ImageF& white,
               const Grid3& grid, double angular_sampling = 1.0, const WeightsSource& source = {});
  // What process_pair needs for `settings`: reconstruction_grid() (the guard slices included) and
  // the settings' angular sampling.
  PairOperator(const optics::CameraModel& camera, const optics::MicrolensArray& lenses, const ImageF& white,
               const ProcessSettings& settings, const WeightsSource& source = {});

  const recon::WeightingOperator& weights() const { return *weights_; }
  // Null when the operator works on raw pixels.
  const lightfield::LatticeResampler* resampler() const { return resampler_.get(); }
  const std::string& note() const { return note_; }
  // A raw frame in the operator's pixel space: `frame` itself, or `scratch` holding it resampled.
  const ImageF& prepare(const ImageF& frame, ImageF& scratch) const;

 private:
  std::unique_ptr<const lightfield::LatticeResampler> resampler_;
  std::unique_ptr<const recon::WeightingOperator> weights_;
  std::string note_;
};

// Reconstructs both frames with `op` (whose grid must be settings.reconstruction_grid():
// InputError otherwise), correlates them with the guard slices as depth context (vectors on
// settings.grid's box only; piv::correlate_volumes), then drops those slices (PairResult's volumes
// are on settings.grid). Images are validated (sensor-sized, finite, non-negative) and named
// "frame A" / "frame B" in errors. Bit-identical at any thread count. Frame B is reconstructed in
// frame A's buffers: in `workspace` when given (a caller processing pair after pair keeps one per
// pair in flight, so that no frame allocates them afresh), else in one kept for the pair. The
// results are the same bits either way. `cancel` (optional): checked before every MART iteration
// and every correlation pass; when it reads true the pair is abandoned with recon::Cancelled.
PairResult process_pair(const recon::WeightingOperator& op, const ImageF& frame_a, const ImageF& frame_b,
                        const ProcessSettings& settings, const PairProgress& progress = {},
                        recon::MartWorkspace* workspace = nullptr, const std::atomic<bool>* cancel = nullptr);
// The same from raw frames through a PairOperator: the frames are validated as raw images, resampled
// when the operator says so, and PairResult::lattice_note carries its note.
PairResult process_pair(const PairOperator& op, const ImageF& frame_a, const ImageF& frame_b,
                        const ProcessSettings& settings, const PairProgress& progress = {},
                        recon::MartWorkspace* workspace = nullptr, const std::atomic<bool>* cancel = nullptr);

}  // namespace plenopiv::process
