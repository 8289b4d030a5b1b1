// One frame pair to a vector field: the run config (volume, MART, correlation, dt) and the
// composition reconstruct A, reconstruct B, correlate, shared by `plenopiv process` and live mode.
#pragma once

#include <array>
#include <filesystem>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <string_view>

#include "core/base/grid.hpp"
#include "core/base/image.hpp"
#include "core/base/yaml_access.hpp"
#include "core/lightfield/lattice_resampling.hpp"
#include "core/optics/camera_model.hpp"
#include "core/optics/microlens_array.hpp"
#include "core/piv/multipass.hpp"
#include "core/piv/settings.hpp"
#include "core/process/black_level.hpp"
#include "core/recon/mart.hpp"
#include "core/recon/weights.hpp"

namespace plenopiv::process {

// Everything one pair needs besides the camera and calibration. Defaults: the paper's MART (mu
// 0.5, 5 iterations) and core/piv's default correlation (piv::CorrelationSettings).
struct ProcessSettings {
  Grid3 grid;  // the volume the user asked for, mm: correlated and returned
  // Depth reconstructed beyond each depth end of `grid`, mm, 0..100; default 1. A particle just
  // outside the box puts its elongated image (about ±1 mm at 4 mm from focus on the sec 5.4
  // camera) into the end slices, where it stays from frame to frame and pulls the correlation's
  // depth peak towards zero. The correlation reads the guard slices as depth context; the
  // results drop them (docs/benchmarks.md, "Reduced ring: knob sweep", the no-depth-guard row).
  double depth_guard_mm = 1.0;
  // (u, v) samples per aperture axis relative to sec 5.2's count (recon::WeightingOperator),
  // (0, 8]; default 1.
  double angular_sampling = 1.0;
  // Raw pixels read as one for the reconstruction, per side, 1..8; default 1 (every pixel). At 2,
  // a camera with ~17 px per microlens is reconstructed from ~8.5 px per lens: a quarter of the
  // sensor-side work (ratios, projections, weight tables), for the lens's angular resolution. The
  // live lane's fast tier on a large sensor. Must divide the sensor's pixel counts (PairProcessor
  // checks; optics::CameraModel::binned, bin_pixels).
  int pixel_binning = 1;
  // w corrected for MART's depth response (depth_response.hpp): the seeding, particles per
  // microlens, of the simulated pairs the response is measured on when the settings are first used
  // (PairProcessor; kept in the weights' disk cache after), [0, 5]; default 0: no correction.
  // About the flow's own seeding: the response depends on it only weakly (docs/accuracy.md, "Depth
  // response"). In a run, plenopivd measures the live lane's while Armed and the quality lane's
  // with its first pair (minutes at paper scale, then kept: docs/daemon.md).
  double depth_response_ppm = 0.0;
  // What PairProcessor takes off each raw frame first (black_level.hpp); default each frame's own
  // level between the microlens images.
  BlackLevel black_level = BlackLevel::between_images;
  recon::MartSettings mart;
  piv::CorrelationSettings correlation;  // dt_s lives here

  int guard_slices() const;           // depth_guard_mm in whole slices (rounded up)
  Grid3 reconstruction_grid() const;  // `grid` with the guard slices at both depth ends
  // The peak memory one pair in flight needs (weight tables, MART buffers, both volumes, the
  // correlation), bytes: the measured peak per reconstructed voxel (docs/benchmarks.md "Speed and
  // memory") times the voxels. What a caller checks before it keeps several pairs in flight.
  double peak_bytes_per_pair() const;
};

// Every setting of `s` as bytes in a fixed order (this build's layout): equal bytes, equal
// processing. What a cache of results computed with the settings keys them on. Leaves out the
// correlation's dt_s (velocities only: displacements, which such results hold, do not depend on
// it). A member added to ProcessSettings, MartSettings, CorrelationSettings or the structs they
// hold does not compile until it is written here too.
std::string settings_key(const ProcessSettings& s);

// The box of voxels centred on [lo, hi] per axis with `voxel_mm` spacing (x, y, z); InputError
// naming `where` when a size is not positive, an axis has min >= max, or the count is absurd.
Grid3 grid_for_extent(const std::array<double, 3>& lo, const std::array<double, 3>& hi,
                      const std::array<double, 3>& voxel_mm, const std::string& where);

// The keys of a processing spec (process.yaml, and the processing part of run.yaml):
//   dt_s: 0.0001                                   (required: the nominal pulse separation, s)
//   volume: {x_mm: [a, b], y_mm: [..], z_mm: [..], voxel_mm: 0.125, voxel_z_mm: 0.125, depth_guard_mm: 1}
//           [a, b] are the faces of the box (the first voxel's lower face, the last one's upper face)
//   reconstruction: {iterations, mu, acceleration, start: mlos|ones, noise_threshold, dark_weight_cutoff,
//                    convergence, angular_sampling, pixel_binning, sensor_blur_sigma_mm, prune,
//                    prune_threshold, prune_scope: volume|slice, depth_response_ppm,
//                    black_level: between_images|none}
//                                                  (ranges: recon::check)
//   correlation: {passes, median, ...}             (piv::correlation_settings_from; ranges: piv::check)
//   live: {volume: {..}, reconstruction: {..}, correlation: {..}}   (optional: the live lane's fast tier,
//         each key overriding the one above it; everything else as above)
inline constexpr std::string_view kProcessKeys[] = {"dt_s", "volume", "reconstruction", "correlation", "live"};

// Which settings of a spec a vector field was made with: the full settings, or the `live:` fast tier.
enum class Tier { full, live };
// "full" or "live": the name files, messages and the command line use.
const char* tier_name(Tier tier);

// A processing spec, parsed and checked once: the full settings (the quality lane, offline
// processing) and, when the config has a `live:` section, the live lane's fast tier.
struct ProcessSpec {
  ProcessSettings full;
  std::optional<ProcessSettings> live;

  // The settings of `tier`; InputError naming `source` when the tier is live and the spec has none.
  const ProcessSettings& settings(Tier tier, const std::string& source) const;
};

// Reads a spec from a mapping holding only kProcessKeys. Unknown keys are refused; every value is
// checked where its owner checks it (recon::check, piv::check, the volume here); InputError names
// the source and key ("(live tier)" for the live section).
ProcessSpec process_spec_from(const YamlMap& root);
ProcessSpec load_process_spec(const std::filesystem::path& path);
// The full settings alone (process_spec_from(root).full).
ProcessSettings process_settings_from(const YamlMap& root);
ProcessSettings load_process_settings(const std::filesystem::path& path);
// The kProcessKeys entries of `root` as a mapping of their own (copied): what a run config hands to
// process_spec_from and what its run folder keeps as process.yaml, so that live, reprocessed and
// batch results read the same text the same way.
YAML::Node processing_part(const YAML::Node& root);
// YAML text for `node` (a spec mapping), with a comment line on top.
std::string spec_text(const YAML::Node& node, const std::string& comment);

// Where the time went and what was skipped.
struct StageTimes {
  double reconstruct_a_s = 0, reconstruct_b_s = 0, correlate_s = 0;
};

struct PairResult {
  Volume volume_a, volume_b;
  recon::SkipReport skipped_a, skipped_b;
  // Each MART iteration's report (live voxels, work, residual), frames A and B.
  std::vector<recon::IterationReport> iterations_a, iterations_b;
  piv::CorrelationResult correlation;
  StageTimes times;
  std::string lattice_note;  // PairOperator::note: why and how the frames were resampled; empty if not
  // Counts PairProcessor took off each raw frame, per tile of the sensor
  // (ProcessSettings::black_level); unmeasured where none.
  BlackLevels black_level_a, black_level_b;
};

// Progress: stage name ("reconstruct A", "reconstruct B", "correlate") and the fraction of the
// whole pair done, in [0, 1].
using PairProgress = std::function<void(const std::string& stage, double fraction)>;

// What every pair of a run is reconstructed with; built once per run, shared read-only by
// concurrent pairs. When the separable weights take the lens array (rectangular, centres within
// recon::kSeparableTolerancePx of their column and row means: recon::separable_lattice), the
// operator works on raw pixels. Otherwise (a calibrated array rotated more than a little, warped,
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
      const optics::CameraModel& camera, const optics::MicrolensArray& lenses, const ImageF& white, const Grid3& grid,
      double angular_sampling)>;

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
  // What MART takes a dark pixel of prepare(`frame`) to have recorded (recon::MartSettings::
  // dark_floor): 0, the image's own floor, for raw pixels; for a resampled frame the raw frame's
  // (recon::dark_floor_of), since the blend's lens weights reach float rounding and its own
  // faintest pixel says nothing of the sensor.
  float dark_floor(const ImageF& frame, float noise_threshold) const;

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
// results are the same bits either way. `progress` is called after every MART iteration and
// correlation pass; a caller cancels the pair by throwing plenopiv::Cancelled from it (the
// workspace is then free for the next pair). `correlation_workspace` (optional): the correlation's
// volume-sized buffers, kept by the caller likewise (piv::CorrelationWorkspace; the same bits).
PairResult process_pair(const recon::WeightingOperator& op, const ImageF& frame_a, const ImageF& frame_b,
                        const ProcessSettings& settings, const PairProgress& progress = {},
                        recon::MartWorkspace* workspace = nullptr,
                        piv::CorrelationWorkspace* correlation_workspace = nullptr);
// The same from raw frames through a PairOperator: the frames are validated as raw images, resampled
// when the operator says so, and PairResult::lattice_note carries its note.
PairResult process_pair(const PairOperator& op, const ImageF& frame_a, const ImageF& frame_b,
                        const ProcessSettings& settings, const PairProgress& progress = {},
                        recon::MartWorkspace* workspace = nullptr,
                        piv::CorrelationWorkspace* correlation_workspace = nullptr);

}  // namespace plenopiv::process
