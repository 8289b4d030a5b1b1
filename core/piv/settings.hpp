// Settings of the multi-pass correlation: passes (window, overlap), validation, dt; from YAML.
#pragma once

#include <array>
#include <filesystem>
#include <string>
#include <string_view>
#include <vector>

#include "core/base/yaml_access.hpp"
#include "core/piv/deform.hpp"
#include "core/piv/fft_correlator.hpp"
#include "core/piv/validation.hpp"

namespace plenopiv::piv {

struct PassSettings {
  std::array<int, 3> window{32, 32, 32};  // voxels, x y z (elongated in z allowed)
  double overlap_percent = 50;            // 0 <= overlap < 100
  // Voxels by which the second volume's window reaches further in depth at each end, 0..window z;
  // default 0 (the same window in both). Reconstructed particles are streaks several voxels long
  // in depth (paper sec 6.2: elongated about 4 times). A window's depth faces cut them at the
  // same place in both volumes, and the cut ends pull the correlation's depth peak toward zero
  // shift: w comes out short in proportion to the shift still to be measured. With a margin,
  // every piece of a streak in the first window has its whole counterpart in the second, and the
  // correlation, divided at each depth shift by the second window's spread of intensity under the
  // first window, has no such pull. Depth shifts beyond the margin are not searched, so it
  // belongs in passes after the first, whose predictor is already close. FFT size: times
  // (window z + 2 margin) / window z.
  int depth_margin = 0;
  // Voxels between neighbouring windows along `axis`: the window less its overlap, at least 1.
  int step(int axis) const;
};

// What a deformed window's residual is added to. window_mean: the predictor's mean over the
// window's voxels; the passes then converge to the window-averaged (box-filtered) field. centre:
// the predictor at the window's centre; iterated, the passes undo most of the window's
// filtering (the field is measured where the window is, not averaged over it), but an
// alternating (odd-even) error between overlapping windows grows unless the predictor is
// smoothed between passes (Schrijer & Scarano 2008): use it with predictor_smoothing >= 1.
enum class PredictorBase { window_mean, centre };

// Intensities at most this fraction of a volume's peak are numerical dust, not light: values at
// float rounding (float resolves 6e-8 of a value), which interpolation and filtering leave beside
// the light they move. A window of dust alone has a correlation without a peak (its vector and its
// sigma are noise), so it counts as no signal whatever `signal_threshold` says. A reconstructed
// particle's peak varies several-fold with its depth, not a millionfold.
inline constexpr float kNumericalDust = 1e-6f;

// Where the final pass looks for each window's correlation peak. all_shifts: the whole
// correlation, by FFT. near_predictor: the correlation summed directly at the predictor's shift
// and its six face neighbours (direct_correlation.hpp: the FFT's values there, to float rounding),
// and where the value at the predictor is positive and beats all six (find_peaks' test on the
// faces) it is the peak, fitted by the same three-point fits; the passes before leave nearly every
// residual within half a voxel, and the seven sums cost a fraction of the transform. Any other
// window is correlated over all shifts by FFT as before; so is every window whose peak found there
// the median test rejects: that peak stays its primary, and the transform's two highest other
// peaks become the validation's replacements. A vector whose peak was taken at the predictor has
// no second peak: its peak_ratio is NaN. It needs a final pass without a depth margin (that
// normalisation needs every shift).
enum class FinalPeakSearch { all_shifts, near_predictor };

// The names run configs (correlation.predictor, early_interpolation, final_peak_search) and the
// benchmarks give these enums, in the enums' order: the one table they all read.
inline constexpr std::array<std::string_view, 2> kPredictorBaseNames{"window_mean", "centre"};
inline constexpr std::array<std::string_view, 2> kInterpolationNames{"sinc", "cubic"};
inline constexpr std::array<std::string_view, 2> kFinalPeakSearchNames{"all_shifts", "near_predictor"};
std::string_view name_of(PredictorBase base);
std::string_view name_of(Interpolation interpolation);
std::string_view name_of(FinalPeakSearch search);
// The value with that name; InputError naming `what` (the key or option) and the names otherwise.
PredictorBase predictor_base_named(std::string_view name, std::string_view what);
Interpolation interpolation_named(std::string_view name, std::string_view what);
FinalPeakSearch final_peak_search_named(std::string_view name, std::string_view what);

struct CorrelationSettings {
  // Coarse to fine. Pass 1 correlates the volumes as they are; every later pass deforms both
  // volumes by the previous pass's validated field (VODIM). Default: four passes ending at the
  // paper's 16^3 with 75 % overlap; the 16^3, 50 % passes cost an eighth of the final pass's
  // correlations, and each one moves the centre-based predictor closer to the unfiltered field.
  // The first of them reaches 4 voxels further in depth in the second volume (depth_margin), so
  // the passes after it start from the full depth shift; they have no margin, whose
  // normalisation would add more random error than the little bias left there removes
  // (docs/benchmarks.md, "Ring vortex on exact-particle volumes" and "Paper scale: correlation
  // knobs on the same volumes").
  std::vector<PassSettings> passes{{{32, 32, 32}, 50}, {{16, 16, 16}, 50, 4}, {{16, 16, 16}, 50}, {{16, 16, 16}, 75}};
  MedianTest median;
  // A window whose largest intensity in either volume is <= this, or at most kNumericalDust of that
  // volume's peak, has no particle signal.
  float signal_threshold = 0.f;
  double dt_s = 1.0;  // pulse separation: velocity = displacement / dt
  FftPlanning fft_planning = FftPlanning::estimate;
  // Before anything else, each volume loses this multiple of its mean intensity, clipped at zero
  // (subtract_mean_floor in deform.hpp), 0..100; default 0 (off, the paper's correlation). A
  // reconstructed volume's ghosts (the light MART leaves along lines of sight) are a faint haze
  // that moves less than the particles, most of all in depth; the floor removes it from the
  // correlation at a small cost in lateral error. It pays most after few MART iterations; 3-4
  // suits reconstructed volumes, exact-particle volumes need none (docs/benchmarks.md, "Paper
  // scale: time against error" and "Paper scale: correlation knobs on the same volumes").
  double intensity_threshold_of_mean = 0.0;
  // Binomial [1 2 1]/4 smoothing of both volumes before correlating (deform.hpp: why).
  bool prefilter = true;
  // After the prefilter, this many more [1 2 1]/4 passes along depth (z) only, 0..8; needs the
  // prefilter; default 0 (off). A reconstructed particle is ~4 times as long in depth as wide
  // (paper sec 6.2), so depth detail finer than that is reconstruction noise, and this takes it
  // out where a second full prefilter pass would blur the particles laterally too. 4 suits
  // MART's volumes; it blurs exact (round) particles in depth, hence the default
  // (docs/benchmarks.md, "Paper scale: correlation knobs on the same volumes").
  int depth_prefilter = 0;
  PredictorBase predictor = PredictorBase::centre;
  // Binomial [1 2 1]/4 smoothing passes (per axis) over the predictor's nodes before it deforms
  // the next pass: removes the alternating mode the centre predictor lets grow. 0 to 4.
  int predictor_smoothing = 1;
  // Binomial [1 2 1]/4 passes (per axis) over the final field's valid vectors (smooth_valid in
  // validation.hpp), 0..4; default 0 (off, the paper's correlation). A spatial filter after the
  // last pass: it trades resolution (the vortex cores of exact-particle volumes lose a little)
  // for random error, which dominates reconstructed volumes; 1 suits them (docs/benchmarks.md,
  // "Paper scale: correlation knobs on the same volumes").
  int final_smoothing = 0;
  // Estimate each vector's standard uncertainty (VectorField::sigma_*: correlation statistics on
  // the final pass's windows, uncertainty.hpp; carried through final_smoothing); default on. Off:
  // no sigma arrays, and the final pass costs a little less (docs/benchmarks.md, "Per-vector
  // uncertainty"). The vectors are the same bits either way.
  bool uncertainty = true;
  // Nodes apart, per axis, at which the uncertainty is computed from the windows, 1..4; default 1
  // (every vector). With n > 1 it is computed where each index is a multiple of n or the last; a
  // node between takes the trilinear interpolation (in node indices) of its bracketing nodes when
  // each of them has an estimate from a peak at the node's own integer shift, and is computed from
  // its own windows otherwise. Neighbouring windows at 75 % overlap share three quarters of their
  // voxels, so their sigmas change slowly from node to node there; 2 computes about an eighth of
  // them (docs/accuracy.md, "Per-vector uncertainty").
  int uncertainty_stride = 1;
  // The deformation's interpolator in every pass but the last (deform.hpp: Interpolation), whose
  // vectors only become the next pass's predictor; the last pass always deforms with the sinc.
  // Default sinc; cubic makes those passes' deformation cheaper (docs/benchmarks.md,
  // "Paper scale: correlation knobs on the same volumes").
  Interpolation early_interpolation = Interpolation::sinc;
  // Robust phase correlation in every pass but the last (fft_correlator.hpp: SpectralWeights):
  // each window pair's cross-spectrum divided by its magnitude to this power, 0..1; default 0
  // (off: the plain cross-correlation, the paper's), 1: phase correlation. In a MART volume the
  // light left where particles' lines of sight cross moves less than the particles, most in depth,
  // and is broad; evening out the spectrum lets the particles' finer detail set the peak, so the
  // predictor follows w more closely. The last pass, which only measures what the predictor left,
  // stays plain: whitened it adds random error. 1/2 suits MART's volumes (docs/benchmarks.md,
  // "Paper scale: correlation knobs on the same volumes").
  double spectral_whitening = 0.0;
  // The whitened peak's standard deviation per axis (voxels, x y z), 0.5..8: the low-pass that
  // keeps the three-point fits resolvable and the noisy high frequencies out. About a particle's
  // size in each direction: MART's particles at 0.125 x 0.125 x 0.25 mm voxels are ~1 voxel across
  // and ~2 deep. Used only with spectral_whitening > 0.
  std::array<double, 3> whitened_peak_sigma_voxel{1, 1, 2};
  // Where the final pass looks for each window's correlation peak (FinalPeakSearch); default
  // all_shifts, the paper's.
  FinalPeakSearch final_peak_search = FinalPeakSearch::all_shifts;
};

// Checks every value (windows >= 4 voxels, 0 <= overlap < 100, 0 <= depth_margin <= window z,
// threshold and epsilon > 0, radius 1..3, predictor_smoothing and final_smoothing 0..4,
// depth_prefilter 0..8 and only with the prefilter, spectral_whitening 0..1, whitened_peak_sigma_voxel
// 0.5..8 per axis, final_peak_search near_predictor only where the final pass has no depth margin,
// intensity_threshold_of_mean 0..100, dt > 0); InputError naming `source` and the setting otherwise.
void check(const CorrelationSettings& s, const std::string& source);

// Parses "WxHxD@overlap" or "W@overlap" passes, each optionally followed by "+depth_margin",
// comma separated, e.g. "32@50,16@50+4,16x16x32@75".
std::vector<PassSettings> parse_passes(const std::string& text);

// Reads a YAML file:
//   passes: [{window: [32, 32, 32], overlap_percent: 50}, {window: 16, overlap_percent: 50, depth_margin: 4},
//            {window: 16, overlap_percent: 75}]
//   median: {threshold: 2, epsilon_voxel: 0.1, radius: 2}
//   signal_threshold: 0
//   dt_s: 0.001
//   fft_planning: estimate   # or measure (faster; not bit-identical between processes)
//   intensity_threshold_of_mean: 0  # subtract this many times each volume's mean first (ghosts)
//   prefilter: true          # binomial smoothing of both volumes first
//   depth_prefilter: 0       # then this many binomial passes along z only, 0..8 (needs prefilter)
//   predictor: centre        # or window_mean (what a window's residual is added to)
//   predictor_smoothing: 1   # binomial passes over the predictor between passes, 0..4
//   final_smoothing: 0       # binomial passes over the final field's valid vectors, 0..4
//   uncertainty: true        # each vector's standard uncertainty (sigma), or false
//   uncertainty_stride: 1    # computed every n nodes per axis, 1..4, interpolated between
//   early_interpolation: sinc  # or cubic: the deformation's interpolator before the last pass
//   spectral_whitening: 0    # 0..1: robust phase correlation's whitening before the last pass (0: off)
//   whitened_peak_sigma_voxel: [1, 1, 2]  # its peak's width per axis, voxels
//   final_peak_search: all_shifts  # or near_predictor: the final pass's peak looked for there first
// Every key is optional (defaults above); unknown keys are refused. Checked.
CorrelationSettings load_correlation_settings(const std::filesystem::path& path);
// The same from a mapping already parsed (a section of a larger file, e.g. process.yaml).
CorrelationSettings correlation_settings_from(const YamlMap& map);

}  // namespace plenopiv::piv
