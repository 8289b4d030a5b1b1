// MART (eq 9) on the plenoptic weights: the row-action reference, and the simultaneous
// multiplicative production form (SMART) with MLOS start, skipping and a convergence stop.
#pragma once

#include <array>
#include <cstddef>
#include <functional>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "core/base/grid.hpp"
#include "core/base/image.hpp"
#include "core/recon/explicit_matrix.hpp"
#include "core/recon/weights.hpp"

namespace plenopiv::recon {

enum class MartMethod {
  // E_j <- E_j · exp(mu Σ_i w̄_ij ln(I_i / (W E)_i)): every voxel multiplied by the weighted
  // geometric mean of its pixels' ratios (Byrne's SMART; eq 9 applied to all pixels at once with
  // the eq 13 weights). Matrix-free, parallel, production.
  smart,
  // Eq 9 literally: pixel after pixel on the explicit matrix. The small-case reference.
  row_action,
};

enum class MartStart {
  ones,  // E⁰ = 1 (eq 9)
  mlos,  // multiplicative line of sight: E⁰_j = Π_i I_i^(w̄_ij)
};

// A box in object space, mm (inclusive bounds): voxels whose centres lie outside are not solved.
struct RegionMm {
  std::array<double, 3> min_mm{0, 0, 0};
  std::array<double, 3> max_mm{0, 0, 0};
};

// MartSettings::prune_scope.
enum class PruneScope {
  volume,  // the volume's peak
  slice,   // the peak of the voxel's depth slice
};

// The names run configs (core/process) and the CLI (`plenopiv reconstruct`, the benchmarks) give MartStart
// and PruneScope, in the enums' order: the one table they all read.
inline constexpr std::array<std::string_view, 2> kMartStartNames{"ones", "mlos"};
inline constexpr std::array<std::string_view, 2> kPruneScopeNames{"volume", "slice"};
std::string_view name_of(MartStart start);
std::string_view name_of(PruneScope scope);
// The value with that name; InputError naming `what` (the key or option) and the names otherwise.
MartStart mart_start_named(std::string_view name, std::string_view what);
PruneScope prune_scope_named(std::string_view name, std::string_view what);

struct MartSettings {
  MartMethod method = MartMethod::smart;
  MartStart start = MartStart::mlos;
  // The MLOS start raised to this power (ln E times it) before it is scaled to the image's light.
  // A plenoptic MLOS is a geometric mean over the hundreds of pixels a voxel sees, so particles
  // stand only a little above the haze where lines of sight cross; raised, the haze falls far
  // below them, and a prune cut after the start (the neighbourhood's above all: a faint particle is
  // its own neighbourhood's peak) takes it before the first iteration walks it. Against a slice's
  // or the volume's peak a power above 1 also takes faint particles whole (each voxel's start
  // scales as its particle's light to this power). Range [1, kMaxMlosPower]; default 1 (the
  // geometric mean).
  double mlos_power = 1.0;
  int iterations = 5;
  double mu = 0.5;  // relaxation, 0 < mu <= 1
  // Nesterov's momentum on ln E with FISTA's schedule and a gradient restart: the same cost per
  // iteration as SMART (a few operations per voxel), fewer iterations for a converged depth
  // (docs/recon.md, "MART"). Off (default): the paper's iteration.
  bool accelerate = false;
  float noise_threshold = 0.f;  // pixels at or below it count as dark (zero)
  // A dark pixel zeroes a voxel (eq 9: ratio 0) only where the voxel's column and row weights at
  // that pixel both exceed this fraction of their largest value. Fainter dark pixels (where the
  // weights are wider than a real particle image) pull the voxel down as if they had recorded the
  // floor: the noise threshold, or half the faintest lit pixel. 0 applies eq 9 literally: any
  // dark pixel with weight zeroes the voxel. Range [0, 1); default 0.9, chosen by measurement
  // (docs/recon.md, "What is skipped").
  double dark_weight_cutoff = 0.9;
  // What a dark pixel recorded at most, counts, where the image is not the recording itself: a
  // frame resampled onto another lattice (core/process) blends lenses with weights down to float
  // rounding, so its faintest lit pixel says nothing about the sensor; its raw frame's floor
  // (dark_floor_of) does. 0 (default): the image's own floor. Not a config key; finite, >= 0.
  float dark_floor = 0.f;
  double convergence = 0.0;        // stop when the residual changes by less than this fraction
  std::optional<RegionMm> region;  // solve only here
  // The camera's blur at the sensor (diffraction-limited spot, pixel crosstalk) as a Gaussian of
  // this standard deviation, mm. With it MART solves I = B W E: each projection is blurred, and
  // the log-ratios are blurred before the back-projection (B is symmetric, so (B W)^T = W^T B).
  // Sec 5.2's weights model no diffraction; a blurred image matches voxels nearer the focal plane
  // best, and particles come out compressed toward it (docs/recon.md, "Sensor blur"). 0: the
  // weights alone, as the paper. core/sim's diffraction (the paper's sec 4.1) is 0.0052 mm.
  double sensor_blur_sigma_mm = 0.0;
  // One more projection after the last update, for MartResult::final_residual (the cost of half
  // an iteration). Off where nothing reads it (process::process_pair); the volume is the same
  // either way. Default on.
  bool final_residual = true;
  // Value-adaptive active set: after the start and after each iteration, voxels at or below
  // `prune_threshold` times the volume's peak leave the active set (set to 0), and the passes
  // walk only the live ones. MART's update is multiplicative, so a voxel at exactly 0 stays 0:
  // with threshold 0 only those leave and the volume has the same bits as without pruning. Above
  // 0 a faint voxel that might still have grown is dropped: faster, an approximation whose cost
  // docs/benchmarks.md measures ("Sparse reconstruction"). Range [0, 1); default 0.
  double prune_threshold = 0.0;
  // What `prune_threshold` is a fraction of: the whole volume's peak, or the peak of the voxel's
  // own depth slice (z = const). A reconstructed particle's peak varies several-fold with its depth
  // (lowest far from the focal plane, where its light is spread over the most voxels); against the
  // volume's peak the particles of the faint slices are pruned first. Default: volume.
  PruneScope prune_scope = PruneScope::volume;
  // A voxel at or below the prune threshold stays in the active set while a voxel at most this
  // many depth slices away, at the same x and y, is above it. MART's particles are several times
  // longer in depth than wide and the centroid of their faint depth ends carries w; a threshold
  // alone cuts those ends first. Range [0, kMaxPruneDepthReach] slices; default 0 (the value alone).
  int prune_depth_reach = 0;
  // A second cut, against the voxel's neighbourhood instead of its slice: a live voxel at or below
  // this fraction of the brightest voxel near it (in its brick of kLocalPruneBrick voxels or the 26
  // bricks around it) leaves the active set too. It takes the faint light about each particle, the
  // halo MART has not yet gathered into it, where a higher cut against the slice's peak would take
  // faint particles whole: a faint particle is its own neighbourhood's peak. Applies with or without
  // `prune_threshold`, the higher of the two cuts deciding. Range [0, 1); default 0 (off).
  double prune_local_threshold = 0.0;
  // Off: every active voxel is updated on every iteration (the reference). Default on.
  bool prune = true;
};
// MartSettings::mlos_power's upper end: past it the start holds little but each particle's peak.
inline constexpr double kMaxMlosPower = 8.0;
// MartSettings::prune_depth_reach's upper end: a particle's depth extent, in slices, at the
// paper's magnification and aperture is well inside it.
inline constexpr int kMaxPruneDepthReach = 32;
// MartSettings::prune_local_threshold's bricks, voxels along x, y and z: with the bricks around
// it, a neighbourhood of 12 x 12 x 6 voxels, at the paper's voxels (0.125 mm across, 0.25 mm
// deep) 1.5 mm each way: a reconstructed particle and its halo, and a few of its neighbours at
// 0.5 particles per microlens.
inline constexpr std::array<int, 3> kLocalPruneBrick{4, 4, 2};
// A Gaussian wider than this is no sensor blur (the paper's lens images are 0.125 mm across).
inline constexpr double kMaxSensorBlurSigmaMm = 0.05;

// A setting outside its range: the YAML key (as core/process reads it under `reconstruction:`) and
// the reason, e.g. {"mu", "must be in (0, 1], got 1.5"}.
struct SettingProblem {
  std::string key, reason;
};
// The one place MART's ranges are checked (reconstruct() refuses what it finds, core/process names
// the config key): iterations 1..10000, mu (0, 1], noise_threshold and dark_floor finite >= 0, dark_weight_cutoff
// [0, 1), convergence finite >= 0, sensor_blur_sigma_mm [0, kMaxSensorBlurSigmaMm].
std::optional<SettingProblem> check(const MartSettings& settings);

// The sensor blur of MartSettings::sensor_blur_sigma_mm on an image of op's sensor, in place: what
// MART with that setting does to each projection W E.
void apply_sensor_blur(const WeightingOperator& op, double sigma_mm, std::span<float> image);

// What was skipped, so a run can report how much of the box the scene needed.
struct SkipReport {
  std::size_t pixels = 0;
  std::size_t dark_pixels = 0;  // at or below the noise threshold (inside microlens images)
  float dark_floor = 0;         // what MART takes a dark pixel to have recorded, counts
  std::size_t voxels = 0;
  std::size_t voxels_unseen = 0;  // see no pixel (outside the field of view)
  std::size_t voxels_outside_region = 0;
  std::size_t voxels_dark = 0;  // seen by a dark pixel: zero under MART, never updated
  std::size_t voxels_active = 0;
  int slices = 0;
  int slices_empty = 0;  // no active voxel
  // Voxels left out of the active set by pruning (MartSettings::prune), over the whole run.
  std::size_t voxels_pruned = 0;
  // Voxel updates done over the iterations (the live voxels of each iteration, summed), and how
  // many iterations ran.
  std::size_t voxel_updates = 0;
  int iterations = 0;
  // The kernels' work over the iterations (ActiveSet::pass_work, summed) against the start's
  // active set's work times the iterations.
  double work_done = 0, work_unpruned = 0;
  double fraction_work_pruned() const { return work_unpruned > 0 ? 1.0 - work_done / work_unpruned : 0.0; }
  // Share of the box not solved at all (dark, unseen, outside the region).
  double fraction_skipped() const { return voxels ? 1.0 - double(voxels_active) / double(voxels) : 0.0; }
  // Share of the box's voxel updates over the iterations that were not done (not solved, or
  // pruned): 1 - voxel_updates / (iterations x voxels).
  double fraction_updates_skipped() const {
    const double all = double(voxels) * double(iterations);
    return all > 0 ? 1.0 - double(voxel_updates) / all : fraction_skipped();
  }
};

struct IterationReport {
  int iteration = 0;    // 1-based
  double residual = 0;  // ||I - W E|| / ||I|| (B W E with the sensor blur) before the update
  double seconds = 0;
  std::size_t live_voxels = 0;  // voxels this iteration updated
  std::size_t voxels = 0;       // in the box
  // This iteration's kernel work (ActiveSet::pass_work) against the start's active set's: below 1
  // once pruning has shrunk the set.
  double work_fraction = 1.0;
  // Share of the box's voxels this iteration did not update.
  double fraction_skipped() const { return voxels ? 1.0 - double(live_voxels) / double(voxels) : 0.0; }
};

// Called after each iteration.
using IterationCallback = std::function<void(const IterationReport&)>;

struct MartResult {
  Volume volume;
  SkipReport skipped;
  std::vector<IterationReport> iterations;
  // ||I - W E|| / ||I|| after the last update; empty when MartSettings::final_residual is off.
  std::optional<double> final_residual;
  bool converged = false;
  double setup_seconds = 0;  // active set and start
  // The setup's parts (wall seconds): choosing the active voxels, grouping them for the kernels
  // (ActiveSet), and the MLOS start (one back-projection).
  double select_seconds = 0, active_set_seconds = 0, start_seconds = 0;
  // Wall seconds spent pruning (MartSettings::prune), most of it laying out the smaller active
  // sets; inside the iterations' seconds, apart from the prune after the start.
  double prune_seconds = 0;
};

// What a dark pixel of `image` recorded at most, counts: `noise_threshold` when it is above 0, else
// half the faintest lit pixel (half a count for a frame of integer counts); half of kHuge when no
// pixel is lit.
float dark_floor_of(std::span<const float> image, float noise_threshold);

// Checks an image for the reconstruction: sensor-sized, finite, non-negative; InputError otherwise
// naming `source`.
void validate_image(const ImageF& image, const WeightingOperator& op, const char* source);
// The same against a sensor of `width` x `height` pixels (a raw frame before binning).
void validate_image(const ImageF& image, int width, int height, const char* source);
// The size check alone: an image of `image_width` x `image_height` px on that sensor.
void validate_size(int image_width, int image_height, int width, int height, const char* source);

namespace detail {
struct MartBuffers;
}

// The buffers of one reconstruction: the thresholded image, ln I, the projection and log-ratio
// images, the per-voxel arrays, the active-set selection's scratch and the kernels' workspace
// (about the size of four sensor images plus a few arrays per active voxel). A caller that
// reconstructs frame after frame (core/process: frame A then B; the daemon and `plenopiv process
// --run`: pair after pair) keeps one, so that later frames neither allocate these buffers nor
// page-fault and zero them again (docs/recon.md, "Buffers kept across frames").
//
// It carries nothing from one frame to the next: reconstruct writes every buffer before reading
// it, so a volume has the same bits with a new workspace, a used one, or none. It takes any
// operator: the buffers grow to the largest sensor and active set seen and are freed with it.
// One reconstruction at a time: a second one while the first runs is refused (InputError); give
// each concurrent reconstruction its own.
class MartWorkspace {
 public:
  MartWorkspace();
  ~MartWorkspace();
  MartWorkspace(MartWorkspace&&) noexcept;
  MartWorkspace& operator=(MartWorkspace&&) noexcept;

  // Bytes held (the buffers' capacities).
  std::size_t bytes() const;

  // Sizes and writes every buffer for the largest reconstruction `op` can run (every voxel of its
  // grid active), so that reconstructions with `op` afterwards neither allocate these buffers nor
  // page-fault them. A daemon reserves its lanes' workspaces while a run is Armed, so that a lane's
  // first pair does not fault in gigabytes beside the recording. Costs the memory of that
  // reconstruction and one projection and back-projection of the whole box; changes no result.
  // std::logic_error while a reconstruction uses the workspace.
  void reserve(const WeightingOperator& op);

 private:
  std::unique_ptr<detail::MartBuffers> buffers_;
  friend MartResult reconstruct(const WeightingOperator&, const ImageF&, const MartSettings&, MartWorkspace&,
                                const IterationCallback&);
};

// Reconstructs a volume from a raw plenoptic image (float, counts) with the matrix-free operator.
// `progress` (optional) is called after each iteration. Bit-identical at any thread count.
MartResult reconstruct(const WeightingOperator& op, const ImageF& image, const MartSettings& settings,
                       const IterationCallback& progress = {});
// The same in `workspace`'s buffers (the same bits). A caller cancels by throwing
// plenopiv::Cancelled from `progress`; the workspace is then free for the next reconstruction.
MartResult reconstruct(const WeightingOperator& op, const ImageF& image, const MartSettings& settings,
                       MartWorkspace& workspace, const IterationCallback& progress = {});

// The reference: eq 9 row by row on the explicit matrix (rows = pixels in storage order).
Volume reconstruct_row_action(const WeightingOperator& op, const SparseMatrix& w, const ImageF& image,
                              const MartSettings& settings);

}  // namespace plenopiv::recon
