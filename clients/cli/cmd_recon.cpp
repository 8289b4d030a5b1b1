// `plenopiv reconstruct`: one raw plenoptic image to a particle volume (HDF5 and .vti) by MART
// on the matrix-free plenoptic weights.
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <memory>
#include <string>

#include "clients/cli/commands.hpp"
#include "clients/cli/options.hpp"
#include "clients/cli/weights_cache.hpp"
#include "core/base/errors.hpp"
#include "core/calib/calibration_file.hpp"
#include "core/calib/nominal_calibration.hpp"
#include "core/io/hdf5_files.hpp"
#include "core/io/raw_frame.hpp"
#include "core/io/vtk_files.hpp"
#include "core/optics/camera_file.hpp"
#include "core/process/black_level.hpp"
#include "core/process/operator_cache.hpp"
#include "core/process/process.hpp"
#include "core/recon/mart.hpp"
#include "core/recon/weights.hpp"

namespace plenopiv::client {
namespace {

struct ReconOptions {
  std::string camera, image, output, vti, calibration;
  std::vector<double> extent;  // x0 x1 y0 y1 z0 z1, mm
  double voxel_mm = 0.125, voxel_z_mm = 0;
  int iterations = 5;
  double mu = 0.5;
  bool accelerate = false;
  std::string start = "mlos";
  float threshold = 0;
  std::string black_level{process::name_of(process::ProcessSettings{}.black_level)};
  double dark_cutoff = 0.9;
  double convergence = 0;
  double sensor_blur_mm = 0;
  double prune_threshold = 0;
  std::string prune_scope = "volume";
  int prune_depth_reach = 0;
  double prune_local_threshold = 0;
  double mlos_power = 1;
  bool no_prune = false;
  std::string cache_dir;
  bool no_cache = false;
  int threads = 0;
};

Grid3 grid_from(const ReconOptions& o) {
  if (o.extent.size() != 6) throw InputError("--extent: give x0 x1 y0 y1 z0 z1 in mm");
  const double d[3] = {o.voxel_mm, o.voxel_mm, o.voxel_z_mm > 0 ? o.voxel_z_mm : o.voxel_mm};
  Grid3 g;
  for (int a = 0; a < 3; ++a) {
    const double lo = o.extent[std::size_t(2 * a)], hi = o.extent[std::size_t(2 * a + 1)];
    if (!(d[a] > 0)) throw InputError("--voxel/--voxel-z: must be positive");
    if (!(hi > lo)) throw InputError("--extent: each axis needs min < max (mm)");
    const long n = std::lround((hi - lo) / d[a]);
    if (n < 1 || n > 100000) throw InputError("--extent/--voxel: " + std::to_string(n) + " voxels along an axis");
    g.shape[a] = int(n);
    g.spacing_mm[a] = d[a];
    // Voxel centres: the box of n voxels centred on the requested extent.
    g.origin_mm[a] = 0.5 * (lo + hi) - 0.5 * (n - 1) * d[a];
  }
  return g;
}

void run(const ReconOptions& o) {
  const auto limit = thread_limit(o.threads);
  const optics::CameraModel camera_file = optics::load_camera_file(o.camera);
  const Grid3 grid = grid_from(o);
  recon::MartSettings s;
  s.iterations = o.iterations;
  s.mu = o.mu;
  s.accelerate = o.accelerate;
  s.noise_threshold = o.threshold;
  s.dark_weight_cutoff = o.dark_cutoff;
  s.convergence = o.convergence;
  s.sensor_blur_sigma_mm = o.sensor_blur_mm;
  s.prune = !o.no_prune;
  s.prune_threshold = o.prune_threshold;
  s.prune_scope = recon::prune_scope_named(o.prune_scope, "--prune-scope");
  s.prune_depth_reach = o.prune_depth_reach;
  s.prune_local_threshold = o.prune_local_threshold;
  s.start = recon::mart_start_named(o.start, "--start");
  s.mlos_power = o.mlos_power;
  const process::BlackLevel black_level = process::black_level_named(o.black_level, "--black-level");
  ImageF image = io::read_raw_frame(o.image);

  const bool tty = ::isatty(STDERR_FILENO);
  const auto t0 = std::chrono::steady_clock::now();
  calib::LoadedCalibration c = o.calibration.empty() ? calib::nominal_calibration(camera_file)
                                                     : calib::load_calibration(o.calibration, camera_file);
  const optics::CameraModel camera = calib::camera_in_frame(camera_file, c);
  optics::MicrolensArray lenses = std::move(c.lenses);
  ImageF white =
      c.white_correction.empty() ? calib::geometric_white_image(camera, lenses) : std::move(c.white_correction);
  // Raw pixels, or the image resampled onto an axis-aligned lattice for a rotated/warped/hex array.
  const auto operators = weights_cache(o.cache_dir, o.no_cache);
  process::OperatorCache::Provenance provenance;
  const std::shared_ptr<const process::PairOperator> kept =
      operators ? operators->get(camera, lenses, white, grid, 1.0, &provenance)
                : std::make_shared<const process::PairOperator>(camera, lenses, white, grid, 1.0);
  if (operators) std::fprintf(stderr, "%s\n", provenance.note.c_str());
  const process::PairOperator& pair_op = *kept;
  const recon::WeightingOperator& op = pair_op.weights();
  recon::validate_image(image, op, o.image.c_str());
  if (black_level == process::BlackLevel::between_images) {
    const process::BlackLevelMeter meter(white);
    const process::BlackLevels levels = meter.measure(image);
    process::subtract_black_level(image, levels);
    std::fprintf(stderr, "%s: %s counts\n", meter.describe().c_str(), levels.text().c_str());
  }
  ImageF scratch;
  const ImageF& prepared = pair_op.prepare(image, scratch);
  s.dark_floor = pair_op.dark_floor(image, s.noise_threshold);
  const double setup = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  std::fprintf(stderr, "weights: %d x %d x %d voxels, %s (%.1f s)\n", grid.shape[0], grid.shape[1], grid.shape[2],
               o.calibration.empty() ? "nominal lattice, geometric white image" : o.calibration.c_str(), setup);
  if (!pair_op.note().empty()) std::fprintf(stderr, "%s\n", pair_op.note().c_str());
  double elapsed = 0;
  const recon::MartResult r = recon::reconstruct(op, prepared, s, [&](const recon::IterationReport& it) {
    elapsed += it.seconds;
    const double rate = it.iteration / std::max(elapsed, 1e-9);
    const double eta = (s.iterations - it.iteration) / rate;
    if (tty) {
      const int width = 30, done = width * it.iteration / s.iterations;
      std::fprintf(stderr, "\r[%s%s] %d/%d  %.2f it/s  ETA %.0f s  residual %.4f",
                   std::string(std::size_t(done), '#').c_str(), std::string(std::size_t(width - done), ' ').c_str(),
                   it.iteration, s.iterations, rate, eta, it.residual);
      if (it.iteration == s.iterations) std::fprintf(stderr, "\n");
    } else {
      std::fprintf(
          stderr, "iteration %d/%d residual %.4f (%.2f s, ETA %.0f s; %zu live voxels, %.1f %% of the box skipped)\n",
          it.iteration, s.iterations, it.residual, it.seconds, eta, it.live_voxels, 100 * it.fraction_skipped());
    }
  });
  if (tty && r.iterations.size() < std::size_t(s.iterations)) std::fprintf(stderr, "\n");
  const recon::SkipReport& k = r.skipped;
  std::fprintf(stderr,
               "skipped %.1f %% of %zu voxels (seen by a dark pixel %zu, outside the field of view %zu), "
               "%d of %d slices empty, %zu dark pixels (taken at %g counts); voxel updates skipped %.1f %% (%zu voxels "
               "pruned); "
               "final residual %.4f%s\n",
               100 * k.fraction_skipped(), k.voxels, k.voxels_dark, k.voxels_unseen, k.slices_empty, k.slices,
               k.dark_pixels, double(k.dark_floor), 100 * k.fraction_updates_skipped(), k.voxels_pruned,
               r.final_residual.value(), r.converged ? " (converged)" : "");
  io::write_volume_h5(o.output, r.volume);
  const std::string vti = o.vti.empty() ? std::filesystem::path(o.output).replace_extension(".vti").string() : o.vti;
  io::write_volume_vti(vti, r.volume);
  std::cout << o.output << "\n" << vti << "\n";
}

}  // namespace

void add_recon_commands(CLI::App& app) {
  auto o = std::make_shared<ReconOptions>();
  auto* cmd = app.add_subcommand(
      "reconstruct",
      "reconstruct a particle volume from one raw plenoptic image (MART, sec 5). Lens centres and the "
      "white correction come from --calibration, else the camera's nominal lattice and the geometric "
      "white image");
  add_camera_option(cmd, o->camera)->required();
  cmd->add_option("image", o->image, "raw plenoptic image (PNG, or TIFF of 8/16-bit or float; sensor-sized)")
      ->required();
  cmd->add_option("--calibration", o->calibration,
                  "calibration file (HDF5 from `plenopiv calibrate`); a rotated, warped or hex array is resampled "
                  "onto an axis-aligned lattice first");
  cmd->add_option("--extent", o->extent, "volume box x0 x1 y0 y1 z0 z1 in mm (z = 0 at the focal plane)")
      ->expected(6)
      ->required();
  cmd->add_option("--voxel", o->voxel_mm, "lateral voxel size, mm")->capture_default_str();
  cmd->add_option("--voxel-z", o->voxel_z_mm, "depth voxel size, mm (default: --voxel)");
  cmd->add_option("--iterations", o->iterations, "MART iterations")->capture_default_str();
  cmd->add_option("--mu", o->mu, "relaxation, 0 < mu <= 1")->capture_default_str();
  cmd->add_flag("--accelerate", o->accelerate,
                "Nesterov momentum on the iterations (about half the iterations for the same depth "
                "recovery; off: the paper's iteration)");
  cmd->add_option("--start", o->start, "initial volume: mlos (multiplicative line of sight) or ones (eq 9)")
      ->check(CLI::IsMember(std::vector<std::string>(recon::kMartStartNames.begin(), recon::kMartStartNames.end())))
      ->capture_default_str();
  cmd->add_option("--threshold", o->threshold,
                  "noise floor in counts: pixels at or below are dark (after the black level is taken off)")
      ->capture_default_str();
  cmd->add_option("--black-level", o->black_level,
                  "taken off the image first: between_images (its median between the microlens images: the "
                  "sensor's pedestal and background) or none (an image already dark-subtracted)")
      ->check(
          CLI::IsMember(std::vector<std::string>(process::kBlackLevelNames.begin(), process::kBlackLevelNames.end())))
      ->capture_default_str();
  cmd->add_option("--dark-cutoff", o->dark_cutoff,
                  "a dark pixel zeroes a voxel only where both 1-D weights exceed this fraction of their "
                  "peak (0: eq 9 literally)")
      ->capture_default_str();
  cmd->add_option("--convergence", o->convergence,
                  "stop when the residual changes by less than this fraction (0: run all iterations)")
      ->capture_default_str();
  cmd->add_option("--sensor-blur-mm", o->sensor_blur_mm,
                  "the camera's blur at the sensor as a Gaussian sigma, mm, modelled in MART (diffraction: "
                  "core/sim's is 0.0052; 0: sec 5.2's weights alone)")
      ->capture_default_str();
  cmd->add_option("--prune-threshold", o->prune_threshold,
                  "voxels at or below this fraction of the volume's peak (or their slice's: --prune-scope) leave "
                  "the active set after the start and each iteration (0: only exact zeros, the same volume as "
                  "without pruning)")
      ->capture_default_str();
  cmd->add_option("--prune-scope", o->prune_scope,
                  "what --prune-threshold is a fraction of: the volume's peak, or each depth slice's own "
                  "(run-paper.yaml's and process.yaml's: a faint slice's particles are kept)")
      ->check(CLI::IsMember(std::vector<std::string>(recon::kPruneScopeNames.begin(), recon::kPruneScopeNames.end())))
      ->capture_default_str();
  cmd->add_option("--prune-depth-reach", o->prune_depth_reach,
                  "a voxel at or below the cut stays while one within this many slices of it along depth is "
                  "above (keeps a particle's faint depth ends; 0: off)")
      ->capture_default_str();
  cmd->add_option("--prune-local-threshold", o->prune_local_threshold,
                  "voxels at or below this fraction of the peak near them (12 x 12 x 6 voxels about) leave the "
                  "active set too: a particle's halo goes, a faint particle stays (0: off)")
      ->capture_default_str();
  cmd->add_option("--mlos-power", o->mlos_power,
                  "the MLOS start raised to this power before MART's first iteration (1 to 8): the haze falls "
                  "below the particles, and a cut against the neighbourhood's peak takes it at once")
      ->capture_default_str();
  cmd->add_flag("--no-prune", o->no_prune, "update every active voxel on every iteration (the reference)");
  cmd->add_option("--cache-dir", o->cache_dir,
                  "folder that keeps weight tables between calls (default: $PLENOPIV_CACHE_DIR, "
                  "$XDG_CACHE_HOME/plenopiv or ~/.cache/plenopiv)");
  cmd->add_flag("--no-cache", o->no_cache, "build the weight tables afresh and keep none");
  cmd->add_option("-o,--output", o->output, "output volume (HDF5: /volume, origin_mm, spacing_mm)")->required();
  cmd->add_option("--vti", o->vti, "also write VTK image data here (default: --output with .vti)");
  add_threads_option(cmd, o->threads);
  cmd->callback([o] { run(*o); });
}

}  // namespace plenopiv::client
