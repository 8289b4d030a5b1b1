// End to end on the paper's Gaussian ring vortex (sec 6.4): simulate a pair, reconstruct both
// frames, correlate; RMS error per component (voxels) against the exact displacement, beside the
// same correlation on exact-particle volumes; time per stage, peak memory; a time/accuracy sweep
// of the knobs on the reduced case with its Pareto front.
//
//   bench_e2e [reduced|mid|full] [--no-sweep] [--rays N] [--iterations N --mu X --accelerate]
//             [--dark-cutoff F] [--noise-threshold C] [--sensor-noise E,R,O [--tap-offset D]] [--black-level B]
//             [--seed N] [--brightness-spread S]
//             [--intensity-threshold K] [--final-smoothing K] [--depth-prefilter K]
//             [--spectral-whitening P [--whitened-peak-sigma X,Y,Z]]
//             [--passes P] [--early-interpolation sinc|cubic] [--voxel-z-factor D] [--uncertainty-stride N]
//             [--final-peak-search all_shifts|near_predictor] [--steady]
//             [--time-sweep [--time-repeats N]] [--z-centre MM] [--compare-passes 'P1;P2;...']
//             [--prune-threshold F [--prune-scope volume|slice]] [--prune-local-threshold F] [--mlos-power P]
//             [--depth-response-ppm F]
//             [--sparse-sweep [--sparse-repeats N] [--sparse-variants V,..]]
//             [--live B,K,N,P ... [--live-depth-prefilter K] [--live-prune-threshold T]
//              [--live-prune-local-threshold T] [--live-only]]
//     --iterations/--mu/--accelerate/--dark-cutoff: MART for the headline rows (default the
//              paper's 5 at mu 0.5, not accelerated, MartSettings' dark-pixel cutoff; the sweep's
//              rows still start from the paper's settings).
//     --noise-threshold C: MART's noise threshold for the headline rows, counts (default 0).
//     --sensor-noise E,R,O: the pair rendered through a real sensor's response instead of one
//              count per ray: E photo-electrons per ray with their shot noise, R electrons of
//              Gaussian read noise, a pedestal of O counts, one count per electron, 12 bits (the
//              simulated camera's `noise=1` is 4,8,20). Every row sees those frames.
//     --tap-offset D: with --sensor-noise, the sensor's right half read out D >= 0 counts higher
//              (a second tap's offset, sim::SensorModel::right_half_offset_dn; default 0).
//     --seed N: the particles' seed (default 2015).
//     --brightness-spread S: each particle's light a log-normal factor with S the spread of its log
//              (sim::RenderOptions::brightness_spread; 0 to 3, default 0: every particle the same),
//              the same factor in both frames; the exact-particle rows keep equal particles.
//     --black-level between_images|none: what is taken off each rendered frame before any row
//              (reconstruction.black_level; default between_images, the frame's median between the
//              microlens images; printed as black_level_a and _b).
//     --time-sweep: MART iterations, the ghost floor and the prune cut against time per pair at this scale (with
//              --no-sweep; ten pairs in a kept workspace; rows marked pareto= for plot_e2e.py), and
//              run-paper.yaml's row once more on each lower build of the kernels this CPU runs
//              (core/base/isa.hpp: AVX2, baseline), with whether its vectors are the same bits;
//              --time-repeats N: the rows interleaved N times, each row's time their median
//              (default 1).
//     --voxel-z-factor D: the headline's voxels D times as deep as wide (volume.voxel_z_mm; errors
//              still in the 0.125 mm voxels; window depths and margins in --passes are its voxels).
//     --voxel-xy-divisor N: the headline's voxels 0.125 / N mm across (volume.voxel_mm; N from 1 to 4, 1.5 too,
//              default 1: the lens pitch; errors still in the 0.125 mm voxels, windows in --passes
//              and --whitened-peak-sigma in its voxels; with --voxel-z-factor, as deep as before).
//     --early-interpolation: the deformation of the passes before the last (correlation's
//              early_interpolation; default the sinc); the variants correlate with the other one.
//     --uncertainty-stride N: the headline's per-vector uncertainty computed every N nodes per axis
//              and interpolated between (correlation's uncertainty_stride; default 1: every node).
//     --final-peak-search: where the headline's final pass looks for its peaks (correlation's
//              final_peak_search; default all_shifts); the variants correlate with the other one.
//     --steady: the headline pair again in the kept MART workspace, --steady-repeats N times
//              (default 3): time per pair in a run, their median (the repeat printed in full).
//     --live B,K,N,P: a live tier beside the headline: voxels B times as large (the same box; BzD:
//              B times as large across and D times as deep; BzDpF: F depth prefilter passes), pixels binned K x K
//              (reconstruction.pixel_binning), N MART iterations, passes P (--passes
//              syntax, windows in its voxels); its set-up, first and in-a-run time per pair and its
//              errors in the headline's voxels (axis band: half its final window) (row
//              variant=live; correlated without spectral whitening and with every vector's own
//              sigma, as run-paper.yaml's live tier), beside the same passes on exact-particle
//              volumes of its grid (exact_*).
//              Repeat for several tiers.
//     --live-depth-prefilter K: the --live tiers' depth prefilter (default the headline's).
//     --live-prune-threshold T: the --live tiers' MART prune cut, of the same scope (default the
//              headline's; run-paper.yaml's live tier takes 0.1).
//     --live-prune-local-threshold T: the --live tiers' cut against the neighbourhood's peak (default
//              the headline's; run-paper.yaml's live tier takes 0: off).
//     --live-only: the --live tiers alone (with --no-sweep), without the headline rows.
//              Each tier's line has its sigma against its errors off the axis band (ratio_*, within_*)
//              and, with --depth-response-ppm, the tier measures its own response (in setup_s); two
//              more lines (variant=live_peak_search) correlate its volumes again with the final
//              peak searched over all shifts and at the predictor first, side by side.
//     --prune-threshold: MART's prune threshold for the headline rows (default 0: exact zeros);
//              --prune-scope: of the volume's peak (default) or of each depth slice's.
//     --prune-local-threshold F: the headline's cut against each voxel's neighbourhood's peak
//              (MartSettings::prune_local_threshold; default 0: off).
//     --mlos-power P: the headline's MLOS start raised to P (MartSettings::mlos_power; default 1).
//     --depth-response-ppm F: the headline's w corrected for MART's depth response measured at F
//              particles per microlens (reconstruction.depth_response_ppm; default 0: off); its
//              set-up time is in weights_s.
//     --sparse-sweep: the headline settings with pruning off, on for exact zeros, and at thresholds
//              1e-3 .. 3e-2 of the volume's peak and 1e-2 .. 2e-1 of each depth slice's peak
//              (slice-*; -reachN: MART's prune_depth_reach N), every pair in the kept workspaces
//              (with --no-sweep; rows variant=sparse for docs/benchmarks.md, "Sparse
//              reconstruction"); --sparse-repeats N: the variants interleaved N times, times the
//              medians (default 1); --sparse-variants: a subset of off,zeros,1e-3,3e-3,1e-2,3e-2,
//              slice-1e-2,slice-3e-2,slice-1e-1,slice-2e-1,slice-1e-1-reach2,slice-2e-1-reach2,
//              slice-1e-1-reach4,slice-2e-1-reach4,slice-1e-2-local-5e-2,slice-1e-2-local-1e-1 (-local-T:
//              MART's prune_local_threshold T) starting with off (default all).
//     --intensity-threshold: the correlation's ghost floor for the headline rows, times each
//              volume's mean (default 0, the paper's correlation); they then also print the
//              correlation without it on the same volumes.
//     --final-smoothing: binomial passes over the headline rows' final field, 0 to 4 (default 0,
//              the paper's correlation); they then also print the field with one pass more (below
//              4) and, when it is set, without it.
//     --depth-prefilter: more binomial passes along z after the prefilter for the headline rows,
//              0 to 8 (default 0); they then also print the field with it toggled (0, or 4).
//     --spectral-whitening P, --whitened-peak-sigma X,Y,Z: the correlation's robust phase
//              weighting of the passes before the last for the headline rows (default 0: off; the
//              peak widths in voxels, default core/piv's); the rows then also print it off (or,
//              when off, at 1/2 and 1).
//     --z-centre: depth of the volume's (and the ring's) centre, mm (default 0: the focal plane).
//     --passes: the headline rows' pass list in --passes syntax (default core/piv's).
//     --compare-passes: correlate the headline volumes (and the exact ones) with each pass list
//              too, in --passes syntax (e.g. '32@50,16@50+4,16@50,16@75'), separated by ';'.
//   Every RMS is given over all vectors and, as off_axis_band_*, over the vectors whose final
//   window (16 voxels: half-width 1 mm) does not reach the ring's axis, |x - x_c| and |z - z_c|
//   <= 1 mm (sim::in_ring_axis_band: there the exact u and w jump).
//     reduced: camera-small.yaml (850 x 850 px), 48 x 48 x 48 voxels of 0.125 mm, a ring of 3 mm
//              diameter with r_c = 8 voxels and v_rc = 3 voxels (the paper's ring scaled to fit).
//     full:    camera-fahringer2015.yaml, 300 x 200 x 200 voxels of 0.125 mm, the paper's ring
//              (8 mm diameter, r_c = 40 voxels, v_rc = 8 voxels).
//     mid:     as full, the box cut laterally to 120 x 80 voxels around the ring (a sixth of the
//              cost; the same optics, depth and seeding).
#include <sys/resource.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <string>
#include <vector>

#include "bench/bench_support.hpp"
#include "core/base/errors.hpp"
#include "core/base/isa.hpp"
#include "core/calib/nominal_calibration.hpp"
#include "core/optics/camera_file.hpp"
#include "core/piv/multipass.hpp"
#include "core/process/pair_processor.hpp"
#include "core/process/process.hpp"
#include "core/sim/exact_volume.hpp"
#include "core/sim/field_errors.hpp"
#include "core/sim/flows.hpp"
#include "core/sim/particles.hpp"
#include "core/sim/render.hpp"

using namespace plenopiv;

namespace {

using bench::now_s;

struct Errors {
  double rms[3] = {0, 0, 0};
  double total = 0;
  double valid_fraction = 0;
  double off_band[3] = {0, 0, 0};       // RMS away from the ring's axis band
  double off_band_gain[3] = {0, 0, 0};  // measured against true displacement there (FieldErrors::gain)
};

// RMS error (voxels) over valid nodes against the midpoint displacement d = D(x - d/2) (three
// fixed-point steps: the ring's displacements are several voxels), and the share of valid nodes;
// beside it the RMS over the nodes whose final window does not reach the ring's axis
// (sim::in_ring_axis_band; half-width `band_mm`, default half the default final window, 1 mm at
// 0.125 mm voxels), where the exact u and w jump.
Errors errors_against(const VectorField& f, const sim::RingVortexFlow& flow, double voxel_mm, double band_mm = 0) {
  if (band_mm <= 0) band_mm = 0.5 * piv::CorrelationSettings{}.passes.back().window[0] * voxel_mm;
  const sim::FieldErrors s = sim::field_errors(f, flow, voxel_mm, 3);
  const sim::FieldErrors off = sim::field_errors(
      f, flow, voxel_mm, 3, 0, [&](const sim::Point3& x) { return !sim::in_ring_axis_band(flow, x, band_mm); });
  Errors e;
  for (int a = 0; a < 3; ++a) e.rms[a] = s.rms[a], e.off_band[a] = off.rms[a], e.off_band_gain[a] = off.gain[a];
  e.total = s.rms_total;
  e.valid_fraction = f.grid.count() ? double(s.compared) / double(f.grid.count()) : 0;
  return e;
}

struct Row {
  std::string variant;
  int iterations, passes, window;
  double mu, seconds, rms_total;
  Errors e;
  std::string value = "-";  // the knob's value where the columns above do not show it
};

void print_row(const char* scale, const Row& r, bool pareto) {
  std::printf(
      "bench=e2e case=%s variant=%s value=%s iterations=%d mu=%.2f final_window=%d passes=%d total_s=%.2f "
      "rms_u=%.3f rms_v=%.3f rms_w=%.3f rms=%.3f valid=%.3f off_axis_band_rms_u=%.3f off_axis_band_rms_v=%.3f "
      "off_axis_band_rms_w=%.3f pareto=%s\n",
      scale, r.variant.c_str(), r.value.c_str(), r.iterations, r.mu, r.window, r.passes, r.seconds, r.e.rms[0],
      r.e.rms[1], r.e.rms[2], r.e.total, r.e.valid_fraction, r.e.off_band[0], r.e.off_band[1], r.e.off_band[2],
      pareto ? "yes" : "no");
}

// Every row, marked pareto=yes where no other row is both faster and more accurate.
void print_pareto(const char* scale, const std::vector<Row>& rows) {
  for (const Row& r : rows) {
    bool dominated = false;
    for (const Row& o : rows)
      if (&o != &r && o.seconds <= r.seconds && o.rms_total <= r.rms_total &&
          (o.seconds < r.seconds || o.rms_total < r.rms_total))
        dominated = true;
    print_row(scale, r, !dominated);
  }
}

// Coarse to fine ending at `final` voxels, 75 % overlap after the first pass (50 %).
std::vector<piv::PassSettings> passes_to(int final, int count) {
  std::vector<piv::PassSettings> p;
  for (int k = count - 1; k >= 0; --k) {
    const int w = final + 8 * k;
    p.push_back({{w, w, w}, k == count - 1 && count > 1 ? 50.0 : 75.0});
  }
  return p;
}

}  // namespace

int main(int argc, char** argv) {
  std::string scale = "reduced";
  bool sweep = true;
  std::size_t rays = 5000;
  int iterations = 5;
  bool accelerate = false;
  double mu = 0.5, z_centre = 0.0, dark_cutoff = recon::MartSettings{}.dark_weight_cutoff;
  double noise_threshold = recon::MartSettings{}.noise_threshold;
  std::string sensor_noise;      // --sensor-noise E,R,O; empty: one count per ray
  double tap_offset = 0;         // --tap-offset D: counts added to the sensor's right half
  double brightness_spread = 0;  // --brightness-spread S: log-normal spread of the particles' light
  std::uint64_t seed = 2015;     // --seed N: the particles' seed
  std::string black_level_name{process::name_of(process::ProcessSettings{}.black_level)};
  double sensor_blur_mm = recon::MartSettings{}.sensor_blur_sigma_mm;
  double intensity_threshold = piv::CorrelationSettings{}.intensity_threshold_of_mean;
  double spectral_whitening = piv::CorrelationSettings{}.spectral_whitening;
  std::array<double, 3> whitened_sigma = piv::CorrelationSettings{}.whitened_peak_sigma_voxel;
  int final_smoothing = piv::CorrelationSettings{}.final_smoothing;
  int depth_prefilter = piv::CorrelationSettings{}.depth_prefilter;
  int uncertainty_stride = piv::CorrelationSettings{}.uncertainty_stride;
  piv::FinalPeakSearch final_peak_search = piv::CorrelationSettings{}.final_peak_search;
  std::string final_peak_search_name;  // --final-peak-search, checked below
  bool steady = false, time_sweep = false, sparse_sweep = false, live_only = false;
  int sparse_repeats = 1, time_repeats = 1, steady_repeats = 3;
  std::string sparse_variants;  // empty: all
  double prune_threshold = recon::MartSettings{}.prune_threshold;
  std::string prune_scope = "volume";
  double prune_local_threshold = recon::MartSettings{}.prune_local_threshold;
  double mlos_power = recon::MartSettings{}.mlos_power;
  double depth_response_ppm = 0.0;
  std::string compare_passes;  // pass lists separated by ';'
  std::string passes;          // the headline's passes (--passes syntax); empty: core/piv's default
  piv::Interpolation early_interpolation = piv::CorrelationSettings{}.early_interpolation;
  std::string early_interpolation_name;    // --early-interpolation, checked below
  int depth_voxel_factor = 1;              // the headline's voxels this many times as deep as wide
  double lateral_divisor = 1;              // and 0.125 / this mm across
  int live_depth_prefilter = -1;           // the --live tiers' depth prefilter; < 0: the headline's
  double live_prune_threshold = -1;        // the --live tiers' prune cut; < 0: the headline's
  double live_prune_local_threshold = -1;  // the --live tiers' neighbourhood cut; < 0: the headline's
  std::vector<std::string> live;           // --live B,K,N,P, one per live tier
  for (int i = 1; i < argc; ++i) {
    if (!std::strcmp(argv[i], "--no-sweep"))
      sweep = false;
    else if (!std::strcmp(argv[i], "--rays") && i + 1 < argc)
      rays = std::stoul(argv[++i]);
    else if (!std::strcmp(argv[i], "--iterations") && i + 1 < argc)
      iterations = std::stoi(argv[++i]);
    else if (!std::strcmp(argv[i], "--mu") && i + 1 < argc)
      mu = std::stod(argv[++i]);
    else if (!std::strcmp(argv[i], "--accelerate"))
      accelerate = true;
    else if (!std::strcmp(argv[i], "--z-centre") && i + 1 < argc)
      z_centre = std::stod(argv[++i]);
    else if (!std::strcmp(argv[i], "--dark-cutoff") && i + 1 < argc)
      dark_cutoff = std::stod(argv[++i]);
    else if (!std::strcmp(argv[i], "--noise-threshold") && i + 1 < argc)
      noise_threshold = std::stod(argv[++i]);
    else if (!std::strcmp(argv[i], "--sensor-noise") && i + 1 < argc)
      sensor_noise = argv[++i];
    else if (!std::strcmp(argv[i], "--tap-offset") && i + 1 < argc)
      tap_offset = std::stod(argv[++i]);
    else if (!std::strcmp(argv[i], "--brightness-spread") && i + 1 < argc)
      brightness_spread = std::stod(argv[++i]);
    else if (!std::strcmp(argv[i], "--seed") && i + 1 < argc)
      seed = std::stoull(argv[++i]);
    else if (!std::strcmp(argv[i], "--black-level") && i + 1 < argc)
      black_level_name = argv[++i];
    else if (!std::strcmp(argv[i], "--sensor-blur-mm") && i + 1 < argc)
      sensor_blur_mm = std::stod(argv[++i]);
    else if (!std::strcmp(argv[i], "--spectral-whitening") && i + 1 < argc)
      spectral_whitening = std::stod(argv[++i]);
    else if (!std::strcmp(argv[i], "--whitened-peak-sigma") && i + 1 < argc) {
      if (std::sscanf(argv[++i], "%lf,%lf,%lf", &whitened_sigma[0], &whitened_sigma[1], &whitened_sigma[2]) != 3) {
        std::fprintf(stderr, "bench_e2e: --whitened-peak-sigma takes X,Y,Z voxels, not '%s'\n", argv[i]);
        return 2;
      }
    } else if (!std::strcmp(argv[i], "--intensity-threshold") && i + 1 < argc)
      intensity_threshold = std::stod(argv[++i]);
    else if (!std::strcmp(argv[i], "--final-smoothing") && i + 1 < argc)
      final_smoothing = std::stoi(argv[++i]);
    else if (!std::strcmp(argv[i], "--depth-prefilter") && i + 1 < argc)
      depth_prefilter = std::stoi(argv[++i]);
    else if (!std::strcmp(argv[i], "--uncertainty-stride") && i + 1 < argc)
      uncertainty_stride = std::stoi(argv[++i]);
    else if (!std::strcmp(argv[i], "--final-peak-search") && i + 1 < argc)
      final_peak_search_name = argv[++i];
    else if (!std::strcmp(argv[i], "--steady"))
      steady = true;
    else if (!std::strcmp(argv[i], "--steady-repeats") && i + 1 < argc)
      steady_repeats = std::max(1, std::stoi(argv[++i]));
    else if (!std::strcmp(argv[i], "--time-sweep"))
      time_sweep = true;
    else if (!std::strcmp(argv[i], "--sparse-sweep"))
      sparse_sweep = true;
    else if (!std::strcmp(argv[i], "--sparse-repeats") && i + 1 < argc)
      sparse_repeats = std::max(1, std::stoi(argv[++i]));
    else if (!std::strcmp(argv[i], "--time-repeats") && i + 1 < argc)
      time_repeats = std::max(1, std::stoi(argv[++i]));
    else if (!std::strcmp(argv[i], "--sparse-variants") && i + 1 < argc)
      sparse_variants = argv[++i];
    else if (!std::strcmp(argv[i], "--prune-threshold") && i + 1 < argc)
      prune_threshold = std::stod(argv[++i]);
    else if (!std::strcmp(argv[i], "--prune-scope") && i + 1 < argc)
      prune_scope = argv[++i];
    else if (!std::strcmp(argv[i], "--depth-response-ppm") && i + 1 < argc)
      depth_response_ppm = std::stod(argv[++i]);
    else if (!std::strcmp(argv[i], "--compare-passes") && i + 1 < argc)
      compare_passes = argv[++i];
    else if (!std::strcmp(argv[i], "--passes") && i + 1 < argc)
      passes = argv[++i];
    else if (!std::strcmp(argv[i], "--live-depth-prefilter") && i + 1 < argc)
      live_depth_prefilter = std::stoi(argv[++i]);
    else if (!std::strcmp(argv[i], "--live-prune-threshold") && i + 1 < argc)
      live_prune_threshold = std::stod(argv[++i]);
    else if (!std::strcmp(argv[i], "--live-prune-local-threshold") && i + 1 < argc)
      live_prune_local_threshold = std::stod(argv[++i]);
    else if (!std::strcmp(argv[i], "--prune-local-threshold") && i + 1 < argc)
      prune_local_threshold = std::stod(argv[++i]);
    else if (!std::strcmp(argv[i], "--mlos-power") && i + 1 < argc)
      mlos_power = std::stod(argv[++i]);
    else if (!std::strcmp(argv[i], "--voxel-z-factor") && i + 1 < argc)
      depth_voxel_factor = std::max(1, std::stoi(argv[++i]));
    else if (!std::strcmp(argv[i], "--voxel-xy-divisor") && i + 1 < argc) {
      lateral_divisor = std::atof(argv[++i]);
      if (lateral_divisor < 1 || lateral_divisor > 4) {
        std::fprintf(stderr, "bench_e2e: --voxel-xy-divisor takes 1 to 4, not '%s'\n", argv[i]);
        return 2;
      }
    } else if (!std::strcmp(argv[i], "--early-interpolation") && i + 1 < argc)
      early_interpolation_name = argv[++i];
    else if (!std::strcmp(argv[i], "--live") && i + 1 < argc)
      live.push_back(argv[++i]);
    else if (!std::strcmp(argv[i], "--live-only"))
      live_only = true;
    else
      scale = argv[i];
  }
  if (sweep && (iterations != 5 || mu != 0.5 || accelerate || z_centre != 0.0 || !passes.empty() ||
                early_interpolation != piv::CorrelationSettings{}.early_interpolation || depth_voxel_factor != 1 ||
                lateral_divisor != 1 || dark_cutoff != recon::MartSettings{}.dark_weight_cutoff ||
                noise_threshold != recon::MartSettings{}.noise_threshold ||
                sensor_blur_mm != recon::MartSettings{}.sensor_blur_sigma_mm ||
                intensity_threshold != piv::CorrelationSettings{}.intensity_threshold_of_mean ||
                spectral_whitening != piv::CorrelationSettings{}.spectral_whitening ||
                final_smoothing != piv::CorrelationSettings{}.final_smoothing ||
                depth_prefilter != piv::CorrelationSettings{}.depth_prefilter ||
                uncertainty_stride != piv::CorrelationSettings{}.uncertainty_stride ||
                final_peak_search != piv::CorrelationSettings{}.final_peak_search ||
                prune_threshold != recon::MartSettings{}.prune_threshold || prune_scope != "volume" ||
                prune_local_threshold != recon::MartSettings{}.prune_local_threshold ||
                mlos_power != recon::MartSettings{}.mlos_power || depth_response_ppm != 0.0)) {
    std::fprintf(
        stderr,
        "bench_e2e: "
        "--iterations/--mu/--accelerate/--dark-cutoff/--noise-threshold/--sensor-blur-mm/--intensity-threshold/"
        "--final-smoothing/--depth-prefilter/--spectral-whitening/--passes/--early-interpolation/"
        "--voxel-z-factor/--voxel-xy-divisor/"
        "--uncertainty-stride/--final-peak-search/--z-centre/--prune-threshold/--prune-scope/"
        "--prune-local-threshold/--mlos-power/--depth-response-ppm change the "
        "headline rows only; use them with --no-sweep\n");
    return 2;
  }
  if (tap_offset != 0 && sensor_noise.empty()) {
    std::fprintf(stderr, "bench_e2e: --tap-offset needs --sensor-noise (a sensor's counts)\n");
    return 2;
  }
  if (!(tap_offset >= 0)) {
    std::fprintf(stderr, "bench_e2e: --tap-offset takes counts >= 0\n");
    return 2;
  }
  // mid: the paper's camera and depth with the box cut laterally to the ring (120 x 80 voxels):
  // the full case's optics and seeding at a sixth of its cost.
  const bool mid = scale == "mid";
  const bool full = scale == "full" || mid;
  if (!full && scale != "reduced") {
    std::fprintf(
        stderr,
        "usage: bench_e2e [reduced|mid|full] [--no-sweep] [--rays N] [--iterations N --mu X --accelerate] "
        "[--dark-cutoff F] [--noise-threshold C] [--sensor-noise E,R,O [--tap-offset D]] [--black-level B] [--seed N] "
        "[--brightness-spread S] [--sensor-blur-mm S] "
        "[--intensity-threshold K] [--final-smoothing K] "
        "[--depth-prefilter K] [--spectral-whitening P [--whitened-peak-sigma X,Y,Z]] [--passes P] "
        "[--early-interpolation sinc|cubic] [--voxel-z-factor D] [--voxel-xy-divisor N] [--uncertainty-stride N] "
        "[--final-peak-search all_shifts|near_predictor] [--steady [--steady-repeats N]] [--time-sweep] "
        "[--z-centre MM] [--compare-passes 'P1;P2'] "
        "[--prune-threshold F "
        "[--prune-scope volume|slice]] [--prune-local-threshold F] [--mlos-power P] [--depth-response-ppm F] "
        "[--sparse-sweep [--sparse-repeats N] [--sparse-variants V,..]] [--live B,K,N,P [--live-depth-prefilter K] "
        "[--live-prune-threshold T] [--live-prune-local-threshold T] [--live-only]]\n");
    return 2;
  }
  recon::PruneScope scope = recon::PruneScope::volume;
  process::BlackLevel black_level = process::BlackLevel::between_images;
  try {
    scope = recon::prune_scope_named(prune_scope, "--prune-scope");
    black_level = process::black_level_named(black_level_name, "--black-level");
    if (!final_peak_search_name.empty())
      final_peak_search = piv::final_peak_search_named(final_peak_search_name, "--final-peak-search");
    if (!early_interpolation_name.empty())
      early_interpolation = piv::interpolation_named(early_interpolation_name, "--early-interpolation");
  } catch (const InputError& e) {
    std::fprintf(stderr, "bench_e2e: %s\n", e.what());
    return 2;
  }
  if (live_only && (sweep || live.empty())) {
    std::fprintf(stderr, "bench_e2e: --live-only needs --no-sweep and at least one --live tier\n");
    return 2;
  }
  const std::string dir = std::string(PLENOPIV_SOURCE_DIR) + "/systemd/config/";
  const auto camera = optics::load_camera_file(dir + (full ? "camera-fahringer2015.yaml" : "camera-small.yaml"));
  const double voxel = 0.125;
  const int nx = mid ? 120 : full ? 300 : 48, ny = mid ? 80 : full ? 200 : 48, nz = full ? 200 : 48;
  const double hx = 0.5 * nx * voxel, hy = 0.5 * ny * voxel, hz = 0.5 * nz * voxel;

  process::ProcessSettings settings;
  settings.grid =
      process::grid_for_extent({-hx, -hy, z_centre - hz}, {hx, hy, z_centre + hz},
                               {voxel / lateral_divisor, voxel / lateral_divisor, depth_voxel_factor * voxel}, "bench");
  settings.correlation.dt_s = 1.0;
  settings.mart.iterations = iterations;
  settings.mart.mu = mu;
  settings.mart.accelerate = accelerate;
  settings.mart.dark_weight_cutoff = dark_cutoff;
  settings.mart.noise_threshold = float(noise_threshold);
  settings.mart.sensor_blur_sigma_mm = sensor_blur_mm;
  settings.mart.prune_threshold = prune_threshold;
  settings.mart.prune_scope = scope;
  settings.mart.prune_local_threshold = prune_local_threshold;
  settings.mart.mlos_power = mlos_power;
  settings.depth_response_ppm = depth_response_ppm;
  settings.black_level = black_level;
  settings.correlation.intensity_threshold_of_mean = intensity_threshold;
  settings.correlation.spectral_whitening = spectral_whitening;
  settings.correlation.whitened_peak_sigma_voxel = whitened_sigma;
  settings.correlation.final_smoothing = final_smoothing;
  settings.correlation.depth_prefilter = depth_prefilter;
  settings.correlation.uncertainty_stride = uncertainty_stride;
  settings.correlation.early_interpolation = early_interpolation;
  if (!passes.empty()) settings.correlation.passes = piv::parse_passes(passes);
  settings.correlation.final_peak_search = final_peak_search;
  try {
    piv::check(settings.correlation, "bench_e2e's correlation settings");
  } catch (const InputError& e) {
    std::fprintf(stderr, "bench_e2e: %s\n", e.what());
    return 2;
  }

  sim::RingVortexFlow::Parameters rv;
  rv.voxel_mm = voxel;
  rv.centre_mm = {0, 0, z_centre};
  if (!full) {
    rv.ring_diameter_mm = 3.0;
    rv.core_radius_voxels = 8;
    rv.core_displacement_voxels = 3;
  }
  const sim::RingVortexFlow flow(rv);

  // Seeding 0.5 ppm in the volume (a margin of 1 mm so particles move in and out as in a flow).
  const sim::Box box{{-hx - 1, -hy - 1, z_centre - hz - 1}, {hx + 1, hy + 1, z_centre + hz + 1}};
  const std::size_t count = sim::particle_count_from_ppm(camera, box, 0.5);
  const auto pa = sim::random_particles(box, count, seed);
  const auto pb = sim::displace(pa, flow);
  const calib::LoadedCalibration nominal = calib::nominal_calibration(camera);
  const optics::MicrolensArray& lenses = nominal.lenses;
  sim::RenderOptions ro;
  ro.rays_per_particle = rays;
  ro.brightness_spread = brightness_spread;  // sim::render checks its range
  ro.brightness_seed = seed;
  if (!sensor_noise.empty()) {
    double electrons_per_ray = 0, read_noise = 0, pedestal = 0;
    char tail = 0;
    if (std::sscanf(sensor_noise.c_str(), "%lf,%lf,%lf%c", &electrons_per_ray, &read_noise, &pedestal, &tail) != 3 ||
        !(electrons_per_ray > 0) || !(read_noise >= 0) || !(pedestal >= 0)) {
      std::fprintf(stderr,
                   "bench_e2e: --sensor-noise E,R,O: electrons per ray > 0, read noise (electrons) and pedestal "
                   "(counts) >= 0, not '%s'\n",
                   sensor_noise.c_str());
      return 2;
    }
    ro.sensor.electrons_per_ray = electrons_per_ray;
    ro.sensor.shot_noise = true;
    ro.sensor.read_noise_electrons = read_noise;
    ro.sensor.dark_offset_dn = pedestal;
    ro.sensor.right_half_offset_dn = tap_offset;
    ro.sensor.bit_depth = 12;
  }
  double t = now_s();
  const auto render = [&](const std::vector<sim::Point3>& p, std::uint64_t seed) {
    const auto r = sim::render(camera, lenses, p, ro, seed);
    ImageF f(r.image.width, r.image.height);
    for (std::size_t i = 0; i < f.size(); ++i) f.pixels[i] = r.image.pixels[i];
    return f;
  };
  ImageF a = render(pa, 1), b = render(pb, 2);
  const double render_s = now_s() - t;
  // Taken off once here, as process::PairProcessor does, so that the rows which call process_pair
  // directly see the same frames (PairProcessor then finds nothing more to take off).
  process::BlackLevels black_level_a, black_level_b;
  if (settings.black_level == process::BlackLevel::between_images) {
    const process::BlackLevelMeter meter(nominal.white_correction);
    black_level_a = meter.measure(a);
    black_level_b = meter.measure(b);
    process::subtract_black_level(a, black_level_a);
    process::subtract_black_level(b, black_level_b);
  }

  // The --live tiers, each with its own processor; false on a malformed tier.
  const auto run_live_tiers = [&]() -> bool {
    for (const std::string& tier : live) {
      // A live tier: the same pair and box in coarser voxels from binned pixels, fewer iterations,
      // its own passes.
      const std::size_t c1 = tier.find(','), c2 = tier.find(',', c1 + 1), c3 = tier.find(',', c2 + 1);
      if (c1 == std::string::npos || c2 == std::string::npos || c3 == std::string::npos) {
        std::fprintf(stderr, "bench_e2e: --live B,K,N,P (voxel factor, pixel binning, iterations, passes), not '%s'\n",
                     tier.c_str());
        return false;
      }
      // B, or BzD: voxels B times as large across and D times as deep; a suffix pK: K depth
      // prefilter passes for this tier.
      std::string factors = tier.substr(0, c1);
      int tier_prefilter = live_depth_prefilter;
      if (const std::size_t pk = factors.find('p'); pk != std::string::npos) {
        tier_prefilter = std::stoi(factors.substr(pk + 1));
        factors = factors.substr(0, pk);
      }
      const std::size_t zd = factors.find('z');
      const int voxel_factor = std::stoi(factors.substr(0, zd));
      const int depth_factor = zd == std::string::npos ? voxel_factor : std::stoi(factors.substr(zd + 1));
      process::ProcessSettings s = settings;
      const double lv = voxel_factor * voxel, lz = depth_factor * voxel;
      s.grid = process::grid_for_extent({-hx, -hy, z_centre - hz}, {hx, hy, z_centre + hz}, {lv, lv, lz}, "bench live");
      s.pixel_binning = std::stoi(tier.substr(c1 + 1, c2 - c1 - 1));
      s.mart.iterations = std::stoi(tier.substr(c2 + 1, c3 - c2 - 1));
      s.correlation.passes = piv::parse_passes(tier.substr(c3 + 1));
      if (tier_prefilter >= 0) s.correlation.depth_prefilter = tier_prefilter;
      if (live_prune_threshold >= 0) s.mart.prune_threshold = live_prune_threshold;
      if (live_prune_local_threshold >= 0) s.mart.prune_local_threshold = live_prune_local_threshold;
      s.correlation.spectral_whitening = 0;  // plain, as run-paper.yaml's live tier
      s.correlation.uncertainty_stride = 1;  // every vector's own, as run-paper.yaml's live tier
      t = now_s();
      const process::PairProcessor live_processor(camera, nominal, s);
      const double setup_s = now_s() - t;
      t = now_s();
      const auto first = live_processor.process(a, b);
      const double first_wall_s = now_s() - t;
      t = now_s();
      const auto again = live_processor.process(a, b);
      const double wall_s = now_s() - t;
      const double band = 0.5 * s.correlation.passes.back().window[0] * lv;
      const Errors el = errors_against(again.correlation.field, flow, voxel, band);
      // The same correlation on exact-particle volumes of this grid: what the tier's voxels and
      // passes allow before any reconstruction error.
      const auto exact = piv::correlate_volumes(sim::render_exact_volume(s.grid, pa),
                                                sim::render_exact_volume(s.grid, pb), s.correlation);
      const Errors ex = errors_against(exact.field, flow, voxel, band);
      // The tier's per-vector sigma against its errors off the axis band: RMS sigma over RMS error,
      // and the errors within 1 and 2 sigma, per component (nan: no sigma).
      std::string sigma_items;
      if (again.correlation.field.has_sigma()) {
        const sim::UncertaintyCheck c =
            sim::uncertainty_check(again.correlation.field, flow, voxel, 3, 0,
                                   [&](const sim::Point3& x) { return !sim::in_ring_axis_band(flow, x, band); });
        for (int k = 0; k < 3; ++k) {
          char item[160];
          std::snprintf(item, sizeof item, " off_axis_band_ratio_%c=%.3f within_1sigma_%c=%.3f within_2sigma_%c=%.3f",
                        "uvw"[k], c.rms_sigma[k] / c.rms_error[k], "uvw"[k], c.within_1[k], "uvw"[k], c.within_2[k]);
          sigma_items += item;
        }
      }
      std::printf(
          "bench=e2e case=%s variant=live tier=%s binning=%d depth_binning=%d depth_prefilter=%d pixel_binning=%d "
          "voxels=%zu iterations=%d prune_threshold=%.3g passes=%s setup_s=%.2f "
          "first_wall_s=%.2f "
          "wall_s=%.2f first_pair_s=%.2f pair_s=%.2f recon_a_s=%.2f recon_b_s=%.2f correlate_s=%.2f rms_u=%.3f "
          "rms_v=%.3f rms_w=%.3f rms=%.3f "
          "valid=%.3f off_axis_band_mm=%.2f off_axis_band_rms_u=%.3f off_axis_band_rms_v=%.3f off_axis_band_rms_w=%.3f "
          "off_axis_band_gain_u=%.3f off_axis_band_gain_v=%.3f off_axis_band_gain_w=%.3f "
          "exact_off_axis_band_rms_u=%.3f exact_off_axis_band_rms_v=%.3f exact_off_axis_band_rms_w=%.3f "
          "depth_response_ppm=%g%s peak_rss_gb=%.2f\n",
          scale.c_str(), tier.c_str(), voxel_factor, depth_factor, s.correlation.depth_prefilter, s.pixel_binning,
          s.grid.count(), s.mart.iterations, s.mart.prune_threshold, tier.substr(c3 + 1).c_str(), setup_s, first_wall_s,
          wall_s, first.times.reconstruct_a_s + first.times.reconstruct_b_s + first.times.correlate_s,
          again.times.reconstruct_a_s + again.times.reconstruct_b_s + again.times.correlate_s,
          again.times.reconstruct_a_s, again.times.reconstruct_b_s, again.times.correlate_s, el.rms[0], el.rms[1],
          el.rms[2], el.total, el.valid_fraction, band, el.off_band[0], el.off_band[1], el.off_band[2],
          el.off_band_gain[0], el.off_band_gain[1], el.off_band_gain[2], ex.off_band[0], ex.off_band[1], ex.off_band[2],
          s.depth_response_ppm, sigma_items.c_str(), bench::peak_rss_gb());
      // The tier's final peak search both ways on the same (cropped) volumes, side by side.
      for (const piv::FinalPeakSearch search :
           {piv::FinalPeakSearch::all_shifts, piv::FinalPeakSearch::near_predictor}) {
        piv::CorrelationSettings c = s.correlation;
        c.final_peak_search = search;
        t = now_s();
        const auto r = piv::correlate_volumes(again.volume_a, again.volume_b, c);
        const double cs = now_s() - t;
        const Errors er = errors_against(r.field, flow, voxel, band);
        std::printf(
            "bench=e2e case=%s variant=live_peak_search tier=%s final_peak_search=%s depth_context=0 correlate_s=%.3f "
            "rms_u=%.3f rms_v=%.3f rms_w=%.3f off_axis_band_rms_u=%.3f off_axis_band_rms_v=%.3f "
            "off_axis_band_rms_w=%.3f valid=%.3f\n",
            scale.c_str(), tier.c_str(), std::string(piv::name_of(search)).c_str(), cs, er.rms[0], er.rms[1], er.rms[2],
            er.off_band[0], er.off_band[1], er.off_band[2], er.valid_fraction);
      }
      std::fflush(stdout);
    }
    return true;
  };
  if (live_only) return run_live_tiers() ? 0 : 2;

  t = now_s();
  // The headline goes through the owner every caller uses (process::PairProcessor); the variants
  // below re-run its operator with other settings.
  const process::PairProcessor processor(camera, nominal, settings);
  const process::PairOperator& op = processor.op();
  const double weights_s = now_s() - t;
  std::printf(
      "bench=e2e case=%s particles=%zu seed=%llu brightness_spread=%g voxels=%zu voxel_mm=%g voxel_z_mm=%g sensor=%s "
      "tap_offset=%g "
      "black_level=%s black_level_a=%g black_level_b=%g black_level_a_range=%g..%g black_level_tiles=%dx%d "
      "noise_threshold=%g render_s=%.2f weights_s=%.2f\n",
      scale.c_str(), count, static_cast<unsigned long long>(seed), brightness_spread, settings.grid.count(),
      settings.grid.spacing_mm[0], settings.grid.spacing_mm[2],
      sensor_noise.empty() ? "one_count_per_ray" : sensor_noise.c_str(), tap_offset, black_level_name.c_str(),
      double(black_level_a.median()), double(black_level_b.median()), double(black_level_a.lowest()),
      double(black_level_a.highest()), black_level_a.tiles_x, black_level_a.tiles_y, noise_threshold, render_s,
      weights_s);

  // The paper's settings: reconstruction and correlation, stage by stage.
  recon::MartWorkspace workspace;  // kept for --steady and the sweeps
  const auto base = processor.process(a, b);
  const Errors e = errors_against(base.correlation.field, flow, voxel);
  std::printf(
      "bench=e2e case=%s variant=reconstructed iterations=%d mu=%.2f accelerate=%d dark_cutoff=%.3g "
      "sensor_blur_mm=%.4g prune_threshold=%.3g prune_scope=%s prune_local_threshold=%.3g mlos_power=%.3g "
      "intensity_threshold=%.3g final_smoothing=%d depth_prefilter=%d recon_a_s=%.2f recon_b_s=%.2f "
      "correlate_s=%.2f skipped_a=%.3f skipped_b=%.3f updates_skipped_a=%.3f updates_skipped_b=%.3f rms_u=%.3f "
      "rms_v=%.3f rms_w=%.3f rms=%.3f valid=%.3f "
      "off_axis_band_rms_u=%.3f off_axis_band_rms_v=%.3f off_axis_band_rms_w=%.3f off_axis_band_gain_u=%.3f "
      "off_axis_band_gain_v=%.3f off_axis_band_gain_w=%.3f peak_rss_gb=%.2f\n",
      scale.c_str(), iterations, mu, int(accelerate), dark_cutoff, sensor_blur_mm, prune_threshold, prune_scope.c_str(),
      prune_local_threshold, mlos_power, intensity_threshold, final_smoothing, depth_prefilter,
      base.times.reconstruct_a_s, base.times.reconstruct_b_s, base.times.correlate_s, base.skipped_a.fraction_skipped(),
      base.skipped_b.fraction_skipped(), base.skipped_a.fraction_updates_skipped(),
      base.skipped_b.fraction_updates_skipped(), e.rms[0], e.rms[1], e.rms[2], e.total, e.valid_fraction, e.off_band[0],
      e.off_band[1], e.off_band[2], e.off_band_gain[0], e.off_band_gain[1], e.off_band_gain[2], bench::peak_rss_gb());
  // The voxels each MART iteration updated (its live set) as a share of the reconstructed box
  // (guard slices included), frame A.
  std::printf("bench=e2e case=%s variant=reconstructed live_share_a=", scale.c_str());
  for (std::size_t i = 0; i < base.iterations_a.size(); ++i)
    std::printf("%s%.3f", i ? "," : "", double(base.iterations_a[i].live_voxels) / double(base.iterations_a[i].voxels));
  std::printf("\n");
  // The per-vector uncertainty off the axis band: RMS sigma over RMS error, and the fraction of true
  // errors within +-1 and +-2 sigma, per component.
  if (base.correlation.field.has_sigma()) {
    const double band_mm = 0.5 * piv::CorrelationSettings{}.passes.back().window[0] * voxel;
    const sim::UncertaintyCheck c =
        sim::uncertainty_check(base.correlation.field, flow, voxel, 3, 0,
                               [&](const sim::Point3& x) { return !sim::in_ring_axis_band(flow, x, band_mm); });
    std::printf("bench=e2e case=%s variant=reconstructed_sigma", scale.c_str());
    for (int a = 0; a < 3; ++a)
      std::printf(" off_axis_band_ratio_%c=%.3f within_1sigma_%c=%.3f within_2sigma_%c=%.3f", "uvw"[a],
                  c.rms_sigma[a] / c.rms_error[a], "uvw"[a], c.within_1[a], "uvw"[a], c.within_2[a]);
    std::printf("\n");
  }

  // Where depth is lost: RMS of w (voxels) per band of the vectors' depth (mm from the focal plane),
  // with the band's gain (slope of measured against true w: below 1 where w falls short in
  // proportion to the motion rather than scattering about it).
  const auto print_w_by_depth = [&](const VectorField& field, const char* volumes) {
    const double edges[] = {-1e9, -8, -4, -2, 0, 2, 4, 8, 1e9};
    std::string bands;
    for (int k = 0; k + 1 < int(std::size(edges)); ++k) {
      const sim::FieldErrors fe = sim::field_errors(field, flow, voxel, 3, 0, [&](const sim::Point3& x) {
        return x[2] - z_centre >= edges[k] && x[2] - z_centre < edges[k + 1];
      });
      char item[256];
      std::snprintf(item, sizeof item, "%s%s..%s:%.3f(%zu,gain=%.3f,u=%.3f,v=%.3f,true_rms_uvw=%.2f/%.2f/%.2f)",
                    k ? "," : "", k ? std::to_string(int(edges[k])).c_str() : "-inf",
                    k + 2 < int(std::size(edges)) ? std::to_string(int(edges[k + 1])).c_str() : "inf", fe.rms[2],
                    fe.compared, fe.gain[2], fe.rms[0], fe.rms[1], fe.truth_rms[0], fe.truth_rms[1], fe.truth_rms[2]);
      bands += item;
    }
    std::printf("bench=e2e case=%s volumes=%s rms_w_by_depth_mm=%s\n", scale.c_str(), volumes, bands.c_str());
  };
  print_w_by_depth(base.correlation.field, "reconstructed");
  if (steady) {
    // The same pair again, the processor's MART buffers kept: what each pair costs in a run of many
    // (the daemon and `plenopiv process --run` keep them from pair to pair). Repeated, and the repeat
    // of median time printed: the machine's speed swings from minute to minute.
    struct Again {
      double pair_s = 0, cpu_s = 0, wall_s = 0;
      process::StageTimes times;
      std::string steps, passes;  // seconds between progress calls; each correlation pass's
      bool same_field = false;
    };
    std::vector<Again> repeats;
    for (int k = 0; k < steady_repeats; ++k) {
      std::vector<double> marks;  // seconds since the start at each progress call
      const double t_again = now_s(), cpu_again = bench::cpu_seconds();
      process::PairOptions timed;
      timed.progress = [&](const std::string&, double) { marks.push_back(now_s() - t_again); };
      const auto again = processor.process(a, b, timed);
      Again& r = repeats.emplace_back();
      r.cpu_s = bench::cpu_seconds() - cpu_again;
      r.wall_s = now_s() - t_again;
      r.times = again.times;
      r.pair_s = again.times.reconstruct_a_s + again.times.reconstruct_b_s + again.times.correlate_s;
      // Per frame set-up with its first iteration, then one per iteration; then the correlation's passes.
      for (std::size_t i = 0; i < marks.size(); ++i) {
        char item[64];
        std::snprintf(item, sizeof item, "%s%.2f", i ? "," : "", marks[i] - (i ? marks[i - 1] : 0.0));
        r.steps += item;
      }
      // Each correlation pass: deformation + correlation + validation s, of which the uncertainty.
      for (const piv::PassReport& p : again.correlation.passes) {
        char item[96];
        std::snprintf(item, sizeof item, "%s%.2f+%.2f+%.2f(%.2f)", r.passes.empty() ? "" : ",", p.deform_s,
                      p.correlate_s, p.validate_s, p.uncertainty_s);
        r.passes += item;
      }
      r.same_field = again.correlation.field.dz_mm == base.correlation.field.dz_mm &&
                     again.correlation.field.dx_mm == base.correlation.field.dx_mm;
    }
    std::vector<std::size_t> order(repeats.size());
    for (std::size_t k = 0; k < order.size(); ++k) order[k] = k;
    std::sort(order.begin(), order.end(),
              [&](std::size_t i, std::size_t j) { return repeats[i].pair_s < repeats[j].pair_s; });
    const Again& mid = repeats[order[order.size() / 2]];
    const bool same_field = std::all_of(repeats.begin(), repeats.end(), [](const Again& r) { return r.same_field; });
    std::printf("bench=e2e case=%s steady_state_marks_s=%s\n", scale.c_str(), mid.steps.c_str());
    std::printf("bench=e2e case=%s steady_state_passes_s=%s\n", scale.c_str(), mid.passes.c_str());
    std::printf(
        "bench=e2e case=%s variant=steady_state repeats=%zu recon_a_s=%.2f recon_b_s=%.2f correlate_s=%.2f pair_s=%.2f "
        "pair_min_s=%.2f pair_max_s=%.2f first_pair_s=%.2f pair_cpu_s=%.2f cores_busy=%.2f same_field=%d\n",
        scale.c_str(), repeats.size(), mid.times.reconstruct_a_s, mid.times.reconstruct_b_s, mid.times.correlate_s,
        mid.pair_s, repeats[order.front()].pair_s, repeats[order.back()].pair_s,
        base.times.reconstruct_a_s + base.times.reconstruct_b_s + base.times.correlate_s, mid.cpu_s,
        mid.cpu_s / mid.wall_s, int(same_field));
    std::fflush(stdout);
  }

  if (!run_live_tiers()) return 2;

  // Baseline: exact-particle volumes through the same correlation (as the paper did).
  t = now_s();
  const Volume ea = sim::render_exact_volume(settings.grid, pa), eb = sim::render_exact_volume(settings.grid, pb);
  const auto exact = piv::correlate_volumes(ea, eb, settings.correlation);
  const Errors ex = errors_against(exact.field, flow, voxel);
  std::printf(
      "bench=e2e case=%s variant=exact_volumes correlate_s=%.2f rms_u=%.3f rms_v=%.3f rms_w=%.3f rms=%.3f "
      "valid=%.3f off_axis_band_rms_u=%.3f off_axis_band_rms_v=%.3f off_axis_band_rms_w=%.3f "
      "off_axis_band_gain_u=%.3f off_axis_band_gain_v=%.3f off_axis_band_gain_w=%.3f\n",
      scale.c_str(), now_s() - t, ex.rms[0], ex.rms[1], ex.rms[2], ex.total, ex.valid_fraction, ex.off_band[0],
      ex.off_band[1], ex.off_band[2], ex.off_band_gain[0], ex.off_band_gain[1], ex.off_band_gain[2]);
  print_w_by_depth(exact.field, "exact");

  // Another correlation of the same volumes (reconstructed, then exact): one row each, labelled
  // `key`=`name`; with `by_depth`, w per depth band for the reconstructed ones as well. These are
  // the cropped volumes PairResult keeps, so unlike the headline (process_pair) they are correlated
  // without the depth guard's slices as depth context (depth_context=0 in the row).
  const auto correlate_both = [&](const char* key, const std::string& name, const piv::CorrelationSettings& c,
                                  bool by_depth) {
    for (bool recon : {true, false}) {
      t = now_s();
      const auto r =
          recon ? piv::correlate_volumes(base.volume_a, base.volume_b, c) : piv::correlate_volumes(ea, eb, c);
      const double cs = now_s() - t;
      const Errors er = errors_against(r.field, flow, voxel);
      std::printf(
          "bench=e2e case=%s %s=%s volumes=%s depth_context=0 correlate_s=%.2f rms_u=%.3f rms_v=%.3f rms_w=%.3f "
          "rms=%.3f "
          "off_axis_band_rms_u=%.3f off_axis_band_rms_v=%.3f off_axis_band_rms_w=%.3f\n",
          scale.c_str(), key, name.c_str(), recon ? "reconstructed" : "exact", cs, er.rms[0], er.rms[1], er.rms[2],
          er.total, er.off_band[0], er.off_band[1], er.off_band[2]);
      if (recon && by_depth) print_w_by_depth(r.field, ("reconstructed_" + name).c_str());
    }
    std::fflush(stdout);
  };

  // Pass schedules from --compare-passes on the same volumes.
  for (std::size_t at = 0; at < compare_passes.size();) {
    const std::size_t end = std::min(compare_passes.find(';', at), compare_passes.size());
    const std::string text = compare_passes.substr(at, end - at);
    at = end + 1;
    piv::CorrelationSettings c = settings.correlation;
    c.passes = piv::parse_passes(text);
    correlate_both("passes", text, c, true);
  }

  // Correlation variants on the same volumes (reconstructed and exact), side by side.
  {
    // Three passes with the residual added to the predictor's window mean, unsmoothed: what the
    // centre predictor, its smoothing and the fourth pass are compared against.
    // Windows of 4 and 2 mm, in the headline's voxels (0.125 / lateral_divisor mm across,
    // depth_voxel_factor times 0.125 mm deep).
    piv::CorrelationSettings previous = settings.correlation;
    const int f = depth_voxel_factor, w32 = int(std::lround(32 * lateral_divisor)),
              w16 = int(std::lround(16 * lateral_divisor));
    previous.passes = {{{w32, w32, std::max(4, 32 / f)}, 50},
                       {{w16, w16, std::max(4, 16 / f)}, 50},
                       {{w16, w16, std::max(4, 16 / f)}, 75}};
    previous.predictor = piv::PredictorBase::window_mean;
    previous.predictor_smoothing = 0;
    piv::CorrelationSettings centre3 = previous;
    centre3.predictor = piv::PredictorBase::centre;
    centre3.predictor_smoothing = 1;
    // The passes without their depth margins.
    piv::CorrelationSettings no_margin = settings.correlation;
    for (piv::PassSettings& p : no_margin.passes) p.depth_margin = 0;
    // The ghost floor toggled: off when the headline has it, 4 when not.
    piv::CorrelationSettings toggled = settings.correlation;
    toggled.intensity_threshold_of_mean = intensity_threshold > 0 ? 0.0 : 4.0;
    correlate_both("correlation", "no_depth_margin", no_margin, false);
    correlate_both("correlation", intensity_threshold > 0 ? "no_intensity_threshold" : "intensity_threshold_4", toggled,
                   false);
    // The final smoothing: one pass more than the headline's (up to the 4 allowed), and none when
    // the headline has some.
    if (final_smoothing < 4) {
      piv::CorrelationSettings smoother = settings.correlation;
      smoother.final_smoothing = final_smoothing + 1;
      correlate_both("correlation", "final_smoothing_" + std::to_string(smoother.final_smoothing), smoother, true);
    }
    if (final_smoothing > 0) {
      piv::CorrelationSettings unsmoothed = settings.correlation;
      unsmoothed.final_smoothing = 0;
      correlate_both("correlation", "final_smoothing_0", unsmoothed, true);
    }
    // The depth prefilter toggled: off when the headline has it, 4 (run-paper.yaml's) when not.
    piv::CorrelationSettings depth_toggled = settings.correlation;
    depth_toggled.depth_prefilter = depth_prefilter > 0 ? 0 : 4;
    correlate_both("correlation", "depth_prefilter_" + std::to_string(depth_toggled.depth_prefilter), depth_toggled,
                   true);
    // The deformation before the last pass with the other interpolator (cubic when the headline's
    // is the sinc).
    piv::CorrelationSettings early = settings.correlation;
    const bool cubic = early.early_interpolation == piv::Interpolation::sinc;
    early.early_interpolation = cubic ? piv::Interpolation::cubic : piv::Interpolation::sinc;
    correlate_both("correlation", cubic ? "early_interpolation_cubic" : "early_interpolation_sinc", early, true);
    // Robust phase correlation: off when the headline has it; at 1/2 and 1 (the headline's peak
    // widths) when not.
    if (spectral_whitening > 0) {
      piv::CorrelationSettings plain = settings.correlation;
      plain.spectral_whitening = 0;
      correlate_both("correlation", "spectral_whitening_0", plain, true);
    } else {
      for (const double p : {0.5, 1.0}) {
        piv::CorrelationSettings whitened = settings.correlation;
        whitened.spectral_whitening = p;
        correlate_both("correlation", p == 1.0 ? "spectral_whitening_1" : "spectral_whitening_0.5", whitened, true);
      }
    }
    // The final pass's peak search the other way.
    piv::CorrelationSettings search = settings.correlation;
    const bool near = final_peak_search == piv::FinalPeakSearch::all_shifts;
    search.final_peak_search = near ? piv::FinalPeakSearch::near_predictor : piv::FinalPeakSearch::all_shifts;
    correlate_both("correlation", near ? "final_peak_search_near_predictor" : "final_peak_search_all_shifts", search,
                   true);
    correlate_both("correlation", "previous_default_3pass_window_mean", previous, false);
    correlate_both("correlation", "centre_3pass", centre3, false);
  }
  if (sparse_sweep) {
    // The value-adaptive active set on this pair: pruning off, exact zeros, then thresholds
    // (fractions of each volume's peak), every pair in the kept workspaces, the variants
    // interleaved `sparse_repeats` times; times (wall, and the process's CPU seconds) are medians. updates_skipped: the
    // share of the box's voxel updates over the iterations not done (not solved, or pruned); work_pruned: the share of
    // the kernels' work the pruning saved against the start's active set.
    struct Prune {
      const char* name;
      bool on;
      double threshold;
      recon::PruneScope scope = recon::PruneScope::volume;
      int depth_reach = 0;
      double local = 0.0;  // MartSettings::prune_local_threshold
    };
    std::vector<Prune> variants;
    constexpr auto slice = recon::PruneScope::slice;
    for (const Prune& pr :
         {Prune{"off", false, 0.0}, Prune{"zeros", true, 0.0}, Prune{"1e-3", true, 1e-3}, Prune{"3e-3", true, 3e-3},
          Prune{"1e-2", true, 1e-2}, Prune{"3e-2", true, 3e-2}, Prune{"slice-1e-2", true, 1e-2, slice},
          Prune{"slice-3e-2", true, 3e-2, slice}, Prune{"slice-1e-1", true, 1e-1, slice},
          Prune{"slice-2e-1", true, 2e-1, slice}, Prune{"slice-1e-1-reach2", true, 1e-1, slice, 2},
          Prune{"slice-2e-1-reach2", true, 2e-1, slice, 2}, Prune{"slice-1e-1-reach4", true, 1e-1, slice, 4},
          Prune{"slice-2e-1-reach4", true, 2e-1, slice, 4}, Prune{"slice-1e-2-local-5e-2", true, 1e-2, slice, 0, 5e-2},
          Prune{"slice-1e-2-local-1e-1", true, 1e-2, slice, 0, 1e-1}})
      if (sparse_variants.empty() ||
          ("," + sparse_variants + ",").find("," + std::string(pr.name) + ",") != std::string::npos)
        variants.push_back(pr);
    if (variants.empty() || variants[0].on) {
      std::fprintf(stderr, "bench_e2e: --sparse-variants must start with off (the reference), e.g. off,zeros,1e-2\n");
      return 2;
    }
    piv::CorrelationWorkspace correlation_workspace;
    // One pair first, untimed: the first variant would pay the kept workspaces' first touch, which
    // a run pays once.
    process::process_pair(op, a, b, settings, {}, &workspace, &correlation_workspace);
    std::vector<std::vector<process::PairResult>> runs(variants.size());
    std::vector<std::vector<double>> cpu(variants.size());  // CPU seconds per pair
    for (int rep = 0; rep < sparse_repeats; ++rep) {
      for (std::size_t v = 0; v < variants.size(); ++v) {
        process::ProcessSettings s = settings;
        s.mart.prune = variants[v].on;
        s.mart.prune_threshold = variants[v].threshold;
        s.mart.prune_scope = variants[v].scope;
        s.mart.prune_depth_reach = variants[v].depth_reach;
        s.mart.prune_local_threshold = variants[v].local;
        const double cpu0 = bench::cpu_seconds();
        process::PairResult r = process::process_pair(op, a, b, s, {}, &workspace, &correlation_workspace);
        cpu[v].push_back(bench::cpu_seconds() - cpu0);
        if (rep > 0) {  // only the times are kept from the repeats (the same bits)
          r.volume_a = {};
          r.volume_b = {};
        }
        runs[v].push_back(std::move(r));
      }
    }
    const auto median = [](std::vector<double> x) {
      std::sort(x.begin(), x.end());
      return x.size() % 2 ? x[x.size() / 2] : 0.5 * (x[x.size() / 2 - 1] + x[x.size() / 2]);
    };
    double off_pair_s = 0, off_cpu_s = 0;
    const process::PairResult& off = runs[0][0];
    for (std::size_t v = 0; v < variants.size(); ++v) {
      std::vector<double> ra, rb, co, pair;
      for (const auto& r : runs[v]) {
        ra.push_back(r.times.reconstruct_a_s);
        rb.push_back(r.times.reconstruct_b_s);
        co.push_back(r.times.correlate_s);
        pair.push_back(r.times.reconstruct_a_s + r.times.reconstruct_b_s + r.times.correlate_s);
      }
      const double pair_s = median(pair);
      const double cpu_s = median(cpu[v]);
      if (v == 0) off_pair_s = pair_s, off_cpu_s = cpu_s;
      const process::PairResult& r = runs[v][0];
      const Errors er = errors_against(r.correlation.field, flow, voxel);
      // The volumes against pruning off: L2 of the difference over L2 of off's.
      double diff = 0, norm = 0;
      for (const auto* pv : {&r.volume_a, &r.volume_b}) {
        const Volume& o = pv == &r.volume_a ? off.volume_a : off.volume_b;
        for (std::size_t i = 0; i < o.data.size(); ++i) {
          diff += (double(pv->data[i]) - o.data[i]) * (double(pv->data[i]) - o.data[i]);
          norm += double(o.data[i]) * o.data[i];
        }
      }
      std::printf(
          "bench=e2e case=%s variant=sparse prune=%s repeats=%d recon_a_s=%.2f recon_b_s=%.2f correlate_s=%.2f "
          "pair_s=%.2f pair_over_off=%.3f pair_cpu_s=%.2f cpu_over_off=%.3f updates_skipped_a=%.3f "
          "updates_skipped_b=%.3f work_pruned_a=%.3f "
          "work_pruned_b=%.3f volume_l2_vs_off=%.4f rms_u=%.3f rms_v=%.3f rms_w=%.3f off_axis_band_rms_u=%.3f "
          "off_axis_band_rms_v=%.3f off_axis_band_rms_w=%.3f valid=%.3f same_field_as_off=%d\n",
          scale.c_str(), variants[v].name, sparse_repeats, median(ra), median(rb), median(co), pair_s,
          off_pair_s > 0 ? pair_s / off_pair_s : 1.0, cpu_s, off_cpu_s > 0 ? cpu_s / off_cpu_s : 1.0,
          r.skipped_a.fraction_updates_skipped(), r.skipped_b.fraction_updates_skipped(),
          r.skipped_a.fraction_work_pruned(), r.skipped_b.fraction_work_pruned(),
          norm > 0 ? std::sqrt(diff / norm) : 0.0, er.rms[0], er.rms[1], er.rms[2], er.off_band[0], er.off_band[1],
          er.off_band[2], er.valid_fraction,
          int(r.correlation.field.dx_mm == off.correlation.field.dx_mm &&
              r.correlation.field.dy_mm == off.correlation.field.dy_mm &&
              r.correlation.field.dz_mm == off.correlation.field.dz_mm));
    }
    std::printf("bench=e2e case=%s peak_rss_gb=%.2f\n", scale.c_str(), bench::peak_rss_gb());
  }
  if (time_sweep) {
    // Time against error at this scale: MART iterations and the ghost floor, every pair in the kept
    // workspace (as in a run of many pairs), so no row pays the first pair's allocations.
    struct Setting {
      std::string name;
      int iterations;
      double mu;
      bool accelerate;
      double floor;
      Isa build = best_isa();
      double prune_threshold = -1;        // MART's cut (the headline's scope); < 0: the headline's
      double prune_local_threshold = -1;  // MART's neighbourhood cut; < 0: the headline's
    };
    std::vector<Row> rows;
    const int np = int(settings.correlation.passes.size());
    process::process_pair(op, a, b, settings, {}, &workspace);  // untimed: the workspace's first touch
    // Floor 3 is the shipped configs' (8 iterations run-paper.yaml's, 20 process.yaml's).
    const std::vector<Setting> settings_swept{{"paper_5_it_mu_0.5", 5, 0.5, false, 0},
                                              {"7_acc_floor_3", 7, 1, true, 3},
                                              {"8_acc_floor_3", 8, 1, true, 3},
                                              {"8_acc_floor_4", 8, 1, true, 4},
                                              {"9_acc_floor_3", 9, 1, true, 3},
                                              {"10_acc_floor_3", 10, 1, true, 3},
                                              {"12_acc_floor_3", 12, 1, true, 3},
                                              {"14_acc_floor_3", 14, 1, true, 3},
                                              // process.yaml's MART: no cut against the neighbourhood's peak.
                                              {"20_acc", 20, 1, true, 0, best_isa(), -1, 0.0},
                                              {"20_acc_floor_3", 20, 1, true, 3, best_isa(), -1, 0.0},
                                              // The prune cut about run-paper.yaml's: none (exact zeros), 3e-2, 1e-1 of
                                              // the slice's peak, and the slice's 1e-2 without the neighbourhood's.
                                              {"8_acc_floor_3_cut_0", 8, 1, true, 3, best_isa(), 0.0, 0.0},
                                              {"8_acc_floor_3_local_0", 8, 1, true, 3, best_isa(), -1, 0.0},
                                              {"8_acc_floor_3_cut_0.03", 8, 1, true, 3, best_isa(), 0.03},
                                              {"8_acc_floor_3_cut_0.1", 8, 1, true, 3, best_isa(), 0.1}};
    // run-paper.yaml's row on the kernels' lower builds.
    std::vector<Setting> swept = settings_swept;
    for (const Isa build : {Isa::avx2, Isa::baseline})
      if (build < best_isa()) swept.push_back({std::string("8_acc_floor_3_") + isa_name(build), 8, 1, true, 3, build});
    const std::size_t reference = std::size_t(  // 8_acc_floor_3 on the best build
        std::find_if(swept.begin(), swept.end(), [](const Setting& st) { return st.name == "8_acc_floor_3"; }) -
        swept.begin());
    std::vector<VectorField> fields(swept.size());
    // Rows in turn, `time_repeats` times, so that the machine's slow and fast minutes fall on all
    // of them; the errors are the first round's (every round gives the same bits).
    std::vector<std::vector<double>> seconds(swept.size());
    for (int round = 0; round < time_repeats; ++round) {
      for (std::size_t k = 0; k < swept.size(); ++k) {
        const Setting& st = swept[k];
        process::ProcessSettings s = settings;
        s.mart.iterations = st.iterations;
        s.mart.mu = st.mu;
        s.mart.accelerate = st.accelerate;
        s.correlation.intensity_threshold_of_mean = st.floor;
        if (st.prune_threshold >= 0) s.mart.prune_threshold = st.prune_threshold;
        if (st.prune_local_threshold >= 0) s.mart.prune_local_threshold = st.prune_local_threshold;
        use_isa(st.build);
        const auto r = process::process_pair(op, a, b, s, {}, &workspace);
        use_isa(best_isa());
        seconds[k].push_back(r.times.reconstruct_a_s + r.times.reconstruct_b_s + r.times.correlate_s);
        if (round == 0) {
          if (k == reference || k >= settings_swept.size()) fields[k] = r.correlation.field;  // compared below
          const Errors er = errors_against(r.correlation.field, flow, voxel);
          Row row{"mart_floor", st.iterations, np, 16, st.mu, 0, er.total, er};
          row.value = st.name;
          rows.push_back(row);
        }
        std::fprintf(stderr, "bench_e2e: %s done (%.1f s)\n", st.name.c_str(), seconds[k].back());
      }
    }
    for (std::size_t k = 0; k < rows.size(); ++k) rows[k].seconds = bench::median(seconds[k]);
    print_pareto(scale.c_str(), rows);
    for (std::size_t k = settings_swept.size(); k < swept.size(); ++k) {
      const VectorField &f = fields[k], &g = fields[reference];
      std::printf(
          "bench=e2e case=%s variant=isa value=%s isa=%s reference_isa=%s s_per_pair=%.2f over_reference=%.3f "
          "same_field_as_reference=%d\n",
          scale.c_str(), swept[k].name.c_str(), isa_name(swept[k].build), isa_name(best_isa()), rows[k].seconds,
          rows[k].seconds / rows[reference].seconds,
          int(f.dx_mm == g.dx_mm && f.dy_mm == g.dy_mm && f.dz_mm == g.dz_mm && f.valid == g.valid));
    }
  }
  if (!sweep) return 0;

  // The sweep: one knob at a time from the paper's settings. Reconstruction knobs re-run both
  // reconstructions; correlation knobs reuse the default volumes (their time adds the default's
  // reconstruction time, as a real run pays it).
  std::vector<Row> rows;
  const double recon_s = base.times.reconstruct_a_s + base.times.reconstruct_b_s;
  const int np = int(settings.correlation.passes.size());  // the default passes
  rows.push_back({"paper", 5, np, 16, 0.5, recon_s + base.times.correlate_s, e.total, e});
  for (int it : {1, 2, 3, 10}) {
    for (double mu : {0.5}) {
      process::ProcessSettings s = settings;
      s.mart.iterations = it;
      s.mart.mu = mu;
      const auto r = process::process_pair(op, a, b, s);
      const Errors er = errors_against(r.correlation.field, flow, voxel);
      rows.push_back({"iterations", it, np, 16, mu,
                      r.times.reconstruct_a_s + r.times.reconstruct_b_s + r.times.correlate_s, er.total, er});
    }
  }
  for (double mu : {0.25, 1.0}) {
    for (int it : {5, 20}) {
      if (mu < 1.0 && it != 5) continue;  // 20 iterations at mu 1: process.yaml's count
      process::ProcessSettings s = settings;
      s.mart.mu = mu;
      s.mart.iterations = it;
      const auto r = process::process_pair(op, a, b, s);
      const Errors er = errors_against(r.correlation.field, flow, voxel);
      rows.push_back({"mu", it, np, 16, mu, r.times.reconstruct_a_s + r.times.reconstruct_b_s + r.times.correlate_s,
                      er.total, er});
    }
  }
  // Acceleration (Nesterov's momentum on ln E): about the same work per iteration, more
  // convergence per iteration.
  for (int it : {5, 10, 20}) {
    process::ProcessSettings s = settings;
    s.mart.mu = 1.0;
    s.mart.iterations = it;
    s.mart.accelerate = true;
    const auto r = process::process_pair(op, a, b, s);
    const Errors er = errors_against(r.correlation.field, flow, voxel);
    rows.push_back({"acceleration", it, np, 16, 1.0,
                    r.times.reconstruct_a_s + r.times.reconstruct_b_s + r.times.correlate_s, er.total, er, "nesterov"});
  }
  {
    // Without the depth guard: particles beyond the depth ends pin light in the end slices.
    process::ProcessSettings s = settings;
    s.depth_guard_mm = 0;
    const process::PairOperator op0(camera, lenses, nominal.white_correction, s);
    const auto r = process::process_pair(op0, a, b, s);
    const Errors er = errors_against(r.correlation.field, flow, voxel);
    rows.push_back({"no_depth_guard", 5, np, 16, 0.5,
                    r.times.reconstruct_a_s + r.times.reconstruct_b_s + r.times.correlate_s, er.total, er});
  }
  // Angular sampling of the weights: (u, v) samples per aperture axis against sec 5.2's count.
  // It sets the cost of the tables (once per run, printed in `value`) and how finely the operator
  // follows the rays; the per-pair time is that of the reconstructions and the correlation.
  for (double sampling : {0.5, 2.0}) {
    process::ProcessSettings s = settings;
    s.angular_sampling = sampling;
    t = now_s();
    const process::PairOperator op_a(camera, lenses, nominal.white_correction, s);
    const double tables_s = now_s() - t;
    const auto r = process::process_pair(op_a, a, b, s);
    const Errors er = errors_against(r.correlation.field, flow, voxel);
    char value[64];
    std::snprintf(value, sizeof value, "%.1fx,tables_%.1fs", sampling, tables_s);
    rows.push_back({"angular_sampling", 5, np, 16, 0.5,
                    r.times.reconstruct_a_s + r.times.reconstruct_b_s + r.times.correlate_s, er.total, er, value});
  }
  // Skip thresholds: the dark-pixel cutoff and a noise floor (counts; the images carry about
  // 5-50 counts in a lit pixel at 5000 rays per particle).
  for (double cutoff : {0.7, 0.99}) {
    process::ProcessSettings s = settings;
    s.mart.dark_weight_cutoff = cutoff;
    const auto r = process::process_pair(op, a, b, s);
    const Errors er = errors_against(r.correlation.field, flow, voxel);
    rows.push_back({"dark_cutoff", 5, np, 16, 0.5,
                    r.times.reconstruct_a_s + r.times.reconstruct_b_s + r.times.correlate_s, er.total, er,
                    std::to_string(cutoff).substr(0, 4)});
  }
  for (float floor_counts : {2.f, 5.f}) {
    process::ProcessSettings s = settings;
    s.mart.noise_threshold = floor_counts;
    const auto r = process::process_pair(op, a, b, s);
    const Errors er = errors_against(r.correlation.field, flow, voxel);
    rows.push_back({"noise_threshold", 5, np, 16, 0.5,
                    r.times.reconstruct_a_s + r.times.reconstruct_b_s + r.times.correlate_s, er.total, er,
                    std::to_string(int(floor_counts))});
  }
  {
    // Volume binning: voxels of twice the size (the same box, windows of the same size in mm).
    process::ProcessSettings s = settings;
    s.grid = process::grid_for_extent({-hx, -hy, -hz}, {hx, hy, hz}, {2 * voxel, 2 * voxel, 2 * voxel}, "bench");
    s.correlation.passes = {{{16, 16, 16}, 50.0}, {{12, 12, 12}, 75.0}, {{8, 8, 8}, 75.0}};
    const process::PairOperator op2(camera, lenses, nominal.white_correction, s);
    const auto r = process::process_pair(op2, a, b, s);
    const Errors er = errors_against(r.correlation.field, flow, voxel);  // still in 0.125 mm voxels
    rows.push_back({"binning", 5, 3, 8, 0.5, r.times.reconstruct_a_s + r.times.reconstruct_b_s + r.times.correlate_s,
                    er.total, er, "2x"});
  }
  // A correlation knob's row: the paper-setting volumes correlated with `c`; its time adds their
  // reconstruction, as a real run pays it.
  const auto correlation_row = [&](const char* variant, const piv::CorrelationSettings& c, int passes, int window,
                                   const std::string& value) {
    t = now_s();
    const auto r = piv::correlate_volumes(base.volume_a, base.volume_b, c);
    const double cs = now_s() - t;
    const Errors er = errors_against(r.field, flow, voxel);
    rows.push_back({variant, 5, passes, window, 0.5, recon_s + cs, er.total, er, value});
  };
  for (int window : {12, 24}) {
    piv::CorrelationSettings c = settings.correlation;
    c.passes = passes_to(window, 3);
    correlation_row("final_window", c, 3, window, "-");
  }
  for (int passes : {1, 2, 4}) {
    piv::CorrelationSettings c = settings.correlation;
    c.passes = passes_to(16, passes);
    correlation_row("passes", c, passes, 16, "-");
  }
  for (int k : {2, 4, 8}) {
    piv::CorrelationSettings c = settings.correlation;
    c.intensity_threshold_of_mean = k;
    correlation_row("intensity_threshold", c, np, 16, std::to_string(k));
  }
  // The depth prefilter: more binomial passes along z after the prefilter (shipped configs: 4).
  for (int k : {2, 4, 8}) {
    piv::CorrelationSettings c = settings.correlation;
    c.depth_prefilter = k;
    correlation_row("depth_prefilter", c, np, 16, std::to_string(k));
  }
  print_pareto(scale.c_str(), rows);
  std::printf("bench=e2e case=%s peak_rss_gb=%.2f\n", scale.c_str(), bench::peak_rss_gb());
  return 0;
}
