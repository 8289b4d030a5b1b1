// One frame pair to a vector field: run config parsing and the reconstruct/correlate composition.
#include "core/process/process.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <limits>
#include <numbers>
#include <span>
#include <sstream>
#include <string>
#include <utility>

#include "core/base/byte_stream.hpp"
#include "core/base/errors.hpp"

namespace plenopiv::process {
namespace {

double seconds_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

std::array<double, 2> range(const YamlMap& m, std::string_view key) {
  const YAML::Node n = m.node()[std::string(key)];
  if (!n) m.fail(key, "missing: give [min, max] in mm");
  if (!n.IsSequence() || n.size() != 2) m.fail(key, "must be [min, max] in mm");
  try {
    return {n[0].as<double>(), n[1].as<double>()};
  } catch (const YAML::Exception&) {
    m.fail(key, "must be two numbers (mm)");
  }
}

// The most voxels a box may have along an axis, and the most slices its depth guard may add at
// each depth face, so that the box with its guard stays well within an int.
constexpr int kMostVoxelsPerAxis = 100000;

}  // namespace

Grid3 grid_for_extent(const std::array<double, 3>& lo, const std::array<double, 3>& hi,
                      const std::array<double, 3>& voxel_mm, const std::string& where) {
  static const char* axis[3] = {"x", "y", "z"};
  Grid3 g;
  for (int a = 0; a < 3; ++a) {
    if (!(voxel_mm[a] > 0) || !std::isfinite(voxel_mm[a]))
      throw InputError(where + ": voxel size along " + axis[a] + " must be > 0 mm");
    if (!(hi[a] > lo[a]) || !std::isfinite(lo[a]) || !std::isfinite(hi[a]))
      throw InputError(where + ": " + axis[a] + " extent needs min < max (mm)");
    const double n = std::round((hi[a] - lo[a]) / voxel_mm[a]);
    if (!(n >= 1 && n <= kMostVoxelsPerAxis)) {
      // n may be far outside any integer type (an extent of 1e300 mm), so it is printed as a double.
      std::ostringstream count;
      count << n;
      throw InputError(where + ": " + count.str() + " voxels along " + axis[a] + " (1.." +
                       std::to_string(kMostVoxelsPerAxis) + ")");
    }
    g.shape[a] = int(n);
    g.spacing_mm[a] = voxel_mm[a];
    g.origin_mm[a] = 0.5 * (lo[a] + hi[a]) - 0.5 * (n - 1) * voxel_mm[a];
  }
  return g;
}

int ProcessSettings::guard_slices() const { return int(std::ceil(depth_guard_mm / grid.spacing_mm[2] - 1e-9)); }

double ProcessSettings::peak_bytes_per_pair() const {
  constexpr double kPeakBytesPerVoxel = 160;
  return double(reconstruction_grid().count()) * kPeakBytesPerVoxel;
}

namespace {

void put_grid(ByteWriter& w, const Grid3& g) {
  const auto& [shape, origin_mm, spacing_mm] = g;
  w.pod(shape);
  w.pod(origin_mm);
  w.pod(spacing_mm);
}

// Structured bindings name every member: a struct with another member count does not compile.
void put_mart(ByteWriter& w, const recon::MartSettings& m) {
  const auto& [method, start, mlos_power, iterations, mu, accelerate, noise_threshold, dark_weight_cutoff, dark_floor,
               convergence, region, sensor_blur_sigma_mm, final_residual, prune_threshold, prune_scope,
               prune_depth_reach, prune_local_threshold, prune] = m;
  w.pod(method);
  w.pod(start);
  w.pod(mlos_power);
  w.pod(iterations);
  w.pod(mu);
  w.pod(accelerate);
  w.pod(noise_threshold);
  w.pod(dark_weight_cutoff);
  w.pod(dark_floor);
  w.pod(convergence);
  w.pod(region.has_value());
  if (region) {
    const auto& [min_mm, max_mm] = *region;
    w.pod(min_mm);
    w.pod(max_mm);
  }
  w.pod(sensor_blur_sigma_mm);
  w.pod(final_residual);
  w.pod(prune_threshold);
  w.pod(prune_scope);
  w.pod(prune_depth_reach);
  w.pod(prune_local_threshold);
  w.pod(prune);
}

void put_correlation(ByteWriter& w, const piv::CorrelationSettings& c) {
  const auto& [passes, median, signal_threshold, dt_s, fft_planning, intensity_threshold_of_mean, prefilter,
               depth_prefilter, predictor, predictor_smoothing, final_smoothing, uncertainty, uncertainty_stride,
               early_interpolation, spectral_whitening, whitened_peak_sigma_voxel, final_peak_search] = c;
  w.pod(std::uint64_t(passes.size()));
  for (const piv::PassSettings& p : passes) {
    const auto& [window, overlap_percent, depth_margin] = p;
    w.pod(window);
    w.pod(overlap_percent);
    w.pod(depth_margin);
  }
  const auto& [threshold, epsilon, radius] = median;
  w.pod(threshold);
  w.pod(epsilon);
  w.pod(radius);
  w.pod(signal_threshold);
  (void)dt_s;  // velocities only
  w.pod(fft_planning);
  w.pod(intensity_threshold_of_mean);
  w.pod(prefilter);
  w.pod(depth_prefilter);
  w.pod(predictor);
  w.pod(predictor_smoothing);
  w.pod(final_smoothing);
  w.pod(uncertainty);
  w.pod(uncertainty_stride);
  w.pod(early_interpolation);
  w.pod(spectral_whitening);
  w.pod(whitened_peak_sigma_voxel);
  w.pod(final_peak_search);
}

}  // namespace

std::string settings_key(const ProcessSettings& s) {
  const auto& [grid, depth_guard_mm, angular_sampling, pixel_binning, depth_response_ppm, black_level, mart,
               correlation] = s;
  std::string out = "plenopiv processing settings\n";
  ByteWriter w(out);
  put_grid(w, grid);
  w.pod(depth_guard_mm);
  w.pod(angular_sampling);
  w.pod(pixel_binning);
  w.pod(depth_response_ppm);
  w.pod(black_level);
  put_mart(w, mart);
  put_correlation(w, correlation);
  return out;
}

Grid3 ProcessSettings::reconstruction_grid() const {
  Grid3 g = grid;
  const int guard = guard_slices();
  g.shape[2] += 2 * guard;
  g.origin_mm[2] -= guard * g.spacing_mm[2];
  return g;
}

namespace {
// The slices [first, first + grid.shape[2]) of `v`, on `grid` (the box the user asked for), in
// place: no second volume-sized buffer per frame.
Volume depth_crop(Volume v, int first, const Grid3& grid) {
  const std::size_t slice = std::size_t(grid.shape[0]) * std::size_t(grid.shape[1]);
  const auto begin = v.data.begin() + std::ptrdiff_t(std::size_t(first) * slice);
  std::move(begin, begin + std::ptrdiff_t(grid.count()), v.data.begin());
  v.data.resize(grid.count());
  v.grid = grid;
  return v;
}

// The correlation's progress after each pass, 0 .. 1: a pass's share of the time is about one
// unit for deforming the volumes plus one per 8 windows per window volume (the product over axes
// of window / step): 2 units for a 16³@50 % pass, 9 for a 16³@75 % pass.
std::vector<double> correlation_progress(const std::vector<piv::PassSettings>& passes) {
  std::vector<double> done;
  double total = 0;
  for (const piv::PassSettings& p : passes) {
    double density = 1;
    for (int a = 0; a < 3; ++a) density *= double(p.window[std::size_t(a)]) / p.step(a);
    total += 1 + density / 8;
    done.push_back(total);
  }
  for (double& d : done) d /= total;
  return done;
}
}  // namespace

namespace {

// dt_s, volume, reconstruction and correlation of one tier.
ProcessSettings parse_settings(const YamlMap& root) {
  root.reject_unknown({"dt_s", "volume", "reconstruction", "correlation"});
  ProcessSettings s;

  const YamlMap vol = root.map("volume");
  vol.reject_unknown({"x_mm", "y_mm", "z_mm", "voxel_mm", "voxel_z_mm", "depth_guard_mm"});
  const auto x = range(vol, "x_mm"), y = range(vol, "y_mm"), z = range(vol, "z_mm");
  const double voxel = vol.number("voxel_mm");
  const double voxel_z = vol.number_or("voxel_z_mm", voxel);
  s.grid = grid_for_extent({x[0], y[0], z[0]}, {x[1], y[1], z[1]}, {voxel, voxel, voxel_z}, root.where("volume"));
  s.depth_guard_mm = vol.number_or("depth_guard_mm", s.depth_guard_mm);
  if (!(s.depth_guard_mm >= 0 && s.depth_guard_mm <= 100)) vol.fail("depth_guard_mm", "must be in [0, 100] mm");
  // The guard is added as whole slices on each face: kept within the box's own bound per axis.
  if (!(s.depth_guard_mm / s.grid.spacing_mm[2] <= kMostVoxelsPerAxis))
    vol.fail("depth_guard_mm", "must be at most " + std::to_string(kMostVoxelsPerAxis) + " slices of voxel_z_mm deep");

  if (auto r = root.optional_map("reconstruction")) {
    r->reject_unknown({"iterations", "mu", "acceleration", "start", "mlos_power", "noise_threshold",
                       "dark_weight_cutoff", "convergence", "angular_sampling", "pixel_binning", "sensor_blur_sigma_mm",
                       "prune", "prune_threshold", "prune_scope", "prune_depth_reach", "prune_local_threshold",
                       "depth_response_ppm", "black_level"});
    // Read here, checked by recon::check (the one owner of MART's ranges); the integer is only kept
    // from wrapping as it narrows.
    s.mart.iterations = r->integer_in("iterations", s.mart.iterations, std::numeric_limits<int>::min(),
                                      std::numeric_limits<int>::max());
    s.mart.mu = r->number_or("mu", s.mart.mu);
    s.mart.accelerate = r->choice_or("acceleration", {"none", "nesterov"}, "none") == "nesterov";
    s.mart.start = recon::mart_start_named(
        r->choice_or("start", recon::kMartStartNames, std::string(recon::name_of(s.mart.start))), "start");
    s.mart.mlos_power = r->number_or("mlos_power", s.mart.mlos_power);
    s.mart.noise_threshold = float(r->number_or("noise_threshold", s.mart.noise_threshold));
    s.mart.dark_weight_cutoff = r->number_or("dark_weight_cutoff", s.mart.dark_weight_cutoff);
    s.mart.convergence = r->number_or("convergence", s.mart.convergence);
    s.mart.sensor_blur_sigma_mm = r->number_or("sensor_blur_sigma_mm", s.mart.sensor_blur_sigma_mm);
    s.mart.prune = r->boolean_or("prune", s.mart.prune);
    s.mart.prune_threshold = r->number_or("prune_threshold", s.mart.prune_threshold);
    s.mart.prune_scope = recon::prune_scope_named(
        r->choice_or("prune_scope", recon::kPruneScopeNames, std::string(recon::name_of(s.mart.prune_scope))),
        "prune_scope");
    s.mart.prune_depth_reach = r->integer_in("prune_depth_reach", s.mart.prune_depth_reach,
                                             std::numeric_limits<int>::min(), std::numeric_limits<int>::max());
    s.mart.prune_local_threshold = r->number_or("prune_local_threshold", s.mart.prune_local_threshold);
    if (const auto problem = recon::check(s.mart)) r->fail(problem->key, problem->reason);
    s.angular_sampling = r->number_or("angular_sampling", s.angular_sampling);
    if (!(s.angular_sampling > 0 && s.angular_sampling <= 8)) r->fail("angular_sampling", "must be in (0, 8]");
    s.pixel_binning = r->integer_in("pixel_binning", s.pixel_binning, 1, 8);
    s.depth_response_ppm = r->number_or("depth_response_ppm", s.depth_response_ppm);
    if (!(s.depth_response_ppm >= 0 && s.depth_response_ppm <= 5))
      r->fail("depth_response_ppm", "must be in [0, 5] particles per microlens (0: off)");
    s.black_level = black_level_named(
        r->choice_or("black_level", kBlackLevelNames, std::string(name_of(s.black_level))), "black_level");
  }

  if (auto c = root.optional_map("correlation")) {
    if (c->has("dt_s")) c->fail("dt_s", "give dt_s once, at the top level");
    s.correlation = piv::correlation_settings_from(*c);
  }
  s.correlation.dt_s = root.number("dt_s");
  if (!(s.correlation.dt_s > 0) || !std::isfinite(s.correlation.dt_s)) root.fail("dt_s", "must be > 0 s");
  piv::check(s.correlation, root.source());
  for (const auto& p : s.correlation.passes)
    for (int a = 0; a < 3; ++a)
      if (p.window[std::size_t(a)] > s.grid.shape[std::size_t(a)])
        root.fail("correlation", "a " + std::to_string(p.window[std::size_t(a)]) +
                                     "-voxel window is larger than the volume (" +
                                     std::to_string(s.grid.shape[std::size_t(a)]) + " voxels along that axis)");
  return s;
}

}  // namespace

ProcessSpec process_spec_from(const YamlMap& root) {
  root.reject_unknown(std::span<const std::string_view>(kProcessKeys));
  YAML::Node full = YAML::Clone(root.node());
  full.remove("live");
  ProcessSpec spec;
  spec.full = parse_settings(YamlMap(full, root.source()));
  if (const auto live = root.optional_map("live")) {
    live->reject_unknown({"volume", "reconstruction", "correlation"});
    // Deep voxels set for the full tier would stay under a live tier's coarser voxel_mm, finer than
    // it across: a tier that changes voxel_mm says its depth too.
    const YAML::Node& full_settings = full;  // read only: no key is added
    if (const auto volume = live->optional_map("volume"); volume && volume->has("voxel_mm") &&
                                                          !volume->has("voxel_z_mm") && full_settings["volume"] &&
                                                          full_settings["volume"]["voxel_z_mm"])
      volume->fail("voxel_z_mm",
                   "missing: the full settings set volume.voxel_z_mm, so a live tier that sets voxel_mm sets "
                   "voxel_z_mm too");
    // Each key of a live section overrides the same key of the full settings' section.
    YAML::Node merged = YAML::Clone(full);
    for (const char* section : {"volume", "reconstruction", "correlation"}) {
      if (!live->has(section)) continue;
      const YamlMap overrides = live->map(section);
      if (!merged[section]) merged[section] = YAML::Node(YAML::NodeType::Map);
      for (const auto& item : overrides.node()) merged[section][item.first.Scalar()] = YAML::Clone(item.second);
    }
    spec.live = parse_settings(YamlMap(merged, root.source() + " (live tier)"));
  }
  return spec;
}

const char* tier_name(Tier tier) { return tier == Tier::live ? "live" : "full"; }

const ProcessSettings& ProcessSpec::settings(Tier tier, const std::string& source) const {
  if (tier == Tier::full) return full;
  if (!live) throw InputError(source + ": has no live: section (the live tier)");
  return *live;
}

ProcessSpec load_process_spec(const std::filesystem::path& path) {
  return process_spec_from(YamlMap(load_yaml_file(path), path.string()));
}

ProcessSettings process_settings_from(const YamlMap& root) { return process_spec_from(root).full; }

ProcessSettings load_process_settings(const std::filesystem::path& path) { return load_process_spec(path).full; }

YAML::Node processing_part(const YAML::Node& root) {
  YAML::Node out(YAML::NodeType::Map);
  for (std::string_view key : kProcessKeys) {
    const std::string k(key);
    if (root[k]) out[k] = YAML::Clone(root[k]);
  }
  return out;
}

std::string spec_text(const YAML::Node& node, const std::string& comment) {
  YAML::Emitter out;
  out.SetDoublePrecision(17);
  out << node;
  std::string text;
  std::istringstream lines(comment);
  for (std::string line; std::getline(lines, line);) text += "# " + line + "\n";
  return text + out.c_str() + "\n";
}

PairResult process_pair(const recon::WeightingOperator& op, const ImageF& frame_a, const ImageF& frame_b,
                        const ProcessSettings& settings, const PairProgress& progress, recon::MartWorkspace* workspace,
                        piv::CorrelationWorkspace* correlation_workspace) {
  if (!(op.grid() == settings.reconstruction_grid()))
    throw InputError(
        "process: the weighting operator was built for another volume grid than the run config's "
        "(its volume plus the depth guard)");
  recon::validate_image(frame_a, op, "frame A");
  recon::validate_image(frame_b, op, "frame B");
  // Shares of the pair's work for the progress fraction: each reconstruction 40 %, correlation 20 %.
  const auto report = [&](const char* stage, double f) {
    if (progress) progress(stage, f);
  };
  const int iterations = settings.mart.iterations;
  recon::MartSettings mart = settings.mart;
  mart.final_residual = false;  // nothing here reads it: one projection less per frame
  PairResult out;
  recon::MartWorkspace pair_workspace;  // no buffers until used
  recon::MartWorkspace& buffers = workspace ? *workspace : pair_workspace;

  auto t0 = std::chrono::steady_clock::now();
  auto ra = recon::reconstruct(op, frame_a, mart, buffers, [&](const recon::IterationReport& it) {
    report("reconstruct A", 0.4 * it.iteration / iterations);
  });
  out.times.reconstruct_a_s = seconds_since(t0);
  out.skipped_a = ra.skipped;
  out.iterations_a = ra.iterations;

  t0 = std::chrono::steady_clock::now();
  auto rb = recon::reconstruct(op, frame_b, mart, buffers, [&](const recon::IterationReport& it) {
    report("reconstruct B", 0.4 + 0.4 * it.iteration / iterations);
  });
  out.times.reconstruct_b_s = seconds_since(t0);
  out.skipped_b = rb.skipped;
  out.iterations_b = rb.iterations;

  // The guard slices are the correlation's depth context: no window lies in them, but the windows
  // at the box's depth faces see the rest of the streaks those faces cut (piv::correlate_volumes).
  t0 = std::chrono::steady_clock::now();
  const std::vector<double> correlated = correlation_progress(settings.correlation.passes);
  out.correlation = piv::correlate_volumes(
      ra.volume, rb.volume, settings.correlation,
      [&](const piv::PassReport& p) { report("correlate", 0.8 + 0.2 * correlated[std::size_t(p.pass - 1)]); },
      settings.guard_slices(), correlation_workspace);
  out.times.correlate_s = seconds_since(t0);
  out.volume_a = depth_crop(std::move(ra.volume), settings.guard_slices(), settings.grid);
  out.volume_b = depth_crop(std::move(rb.volume), settings.guard_slices(), settings.grid);
  report("done", 1.0);
  return out;
}

PairOperator::PairOperator(const optics::CameraModel& camera, const optics::MicrolensArray& lenses, const ImageF& white,
                           const ProcessSettings& settings, const WeightsSource& source)
    : PairOperator(camera, lenses, white, settings.reconstruction_grid(), settings.angular_sampling, source) {}

PairOperator::PairOperator(const optics::CameraModel& camera, const optics::MicrolensArray& lenses, const ImageF& white,
                           const Grid3& grid, double angular_sampling, const WeightsSource& source) {
  const WeightsSource build =
      source ? source
             : [](const optics::CameraModel& c, const optics::MicrolensArray& l, const ImageF& w, const Grid3& g,
                  double a) { return std::make_unique<const recon::WeightingOperator>(c, l, g, w, a); };
  const optics::Lattice& l = lenses.lattice;
  const bool rect = l.layout == optics::LensletLayout::rect;
  const double pixel = camera.sensor().pixel_pitch_mm;
  const recon::SeparableLattice sep = recon::separable_lattice(lenses);
  if (rect && sep.separable(pixel)) {
    weights_ = build(camera, lenses, white, grid, angular_sampling);
    return;
  }
  resampler_ =
      std::make_unique<const lightfield::LatticeResampler>(camera, lenses, white, recon::kSeparableTolerancePx);
  weights_ = build(camera, resampler_->lenses(), resampler_->white(), grid, angular_sampling);
  const auto& c = resampler_->coverage();
  const auto& v = resampler_->lenses().lattice;
  char text[400];
  if (rect) {
    std::snprintf(
        text, sizeof text,
        "image resampled onto an axis-aligned lattice: calibrated array rotated %.2f deg, max departure %.1f px "
        "(the separable weights allow %.2f px); virtual lenses: %d inside the array, %d at its edge, %d beyond; %d "
        "from their nearest lens alone (within %.2f px)",
        l.rotation_rad * 180 / std::numbers::pi, sep.max_departure_mm / pixel, recon::kSeparableTolerancePx, c.full,
        c.partial, c.none, c.nearest, recon::kSeparableTolerancePx);
  } else {
    std::snprintf(text, sizeof text,
                  "image resampled onto an axis-aligned lattice: calibrated array hexagonal (%d x %d lenses, rotated "
                  "%.2f deg), resampled onto %d x %d rectangular lenses one pitch apart; virtual lenses: %d inside "
                  "the array, %d at its edge, %d beyond; %d from their nearest lens alone (within %.2f px)",
                  l.count_x, l.count_y, l.rotation_rad * 180 / std::numbers::pi, v.count_x, v.count_y, c.full,
                  c.partial, c.none, c.nearest, recon::kSeparableTolerancePx);
  }
  note_ = text;
}

const ImageF& PairOperator::prepare(const ImageF& frame, ImageF& scratch) const {
  if (!resampler_) return frame;
  resampler_->resample(frame, scratch);
  return scratch;
}

float PairOperator::dark_floor(const ImageF& frame, float noise_threshold) const {
  return resampler_ ? recon::dark_floor_of({frame.pixels.data(), frame.pixels.size()}, noise_threshold) : 0.f;
}

PairResult process_pair(const PairOperator& op, const ImageF& frame_a, const ImageF& frame_b,
                        const ProcessSettings& settings, const PairProgress& progress, recon::MartWorkspace* workspace,
                        piv::CorrelationWorkspace* correlation_workspace) {
  recon::validate_image(frame_a, op.weights(), "frame A");
  recon::validate_image(frame_b, op.weights(), "frame B");
  // One floor for both frames (process_pair's MART settings are the pair's): the lower.
  ProcessSettings resampled;
  if (op.resampler()) {
    resampled = settings;
    resampled.mart.dark_floor = std::min(op.dark_floor(frame_a, settings.mart.noise_threshold),
                                         op.dark_floor(frame_b, settings.mart.noise_threshold));
  }
  ImageF scratch_a, scratch_b;
  PairResult out = process_pair(op.weights(), op.prepare(frame_a, scratch_a), op.prepare(frame_b, scratch_b),
                                op.resampler() ? resampled : settings, progress, workspace, correlation_workspace);
  out.lattice_note = op.note();
  return out;
}

}  // namespace plenopiv::process
