// Reconstruction benchmarks: paper-scale SMART (phases, memory, skipping) and the matrix-free
// operator against the explicit matrix on a mid-size case, side by side in one process.
#include <sys/resource.h>
#include <tbb/global_control.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <random>
#include <string>

#include "bench/bench_support.hpp"
#include "core/calib/nominal_calibration.hpp"
#include "core/optics/camera_file.hpp"
#include "core/recon/active_set.hpp"
#include "core/recon/explicit_matrix.hpp"
#include "core/recon/mart.hpp"
#include "core/recon/quality.hpp"
#include "core/recon/weights.hpp"
#include "core/sim/exact_volume.hpp"
#include "core/sim/particles.hpp"
#include "core/sim/render.hpp"

using namespace plenopiv;
using Clock = std::chrono::steady_clock;

namespace {

double since(Clock::time_point t) { return std::chrono::duration<double>(Clock::now() - t).count(); }

using bench::cpu_seconds;

// Minor page faults of the process so far (a fresh buffer faults once per page it touches).
long minor_faults() {
  rusage u{};
  getrusage(RUSAGE_SELF, &u);
  return u.ru_minflt;
}

// Particles ray traced by core/sim (the paper's sec 4 simulator: 10 000 rays each, diffraction
// jitter 5.2 um at the microlens plane and the sensor; its defaults), seeded so runs repeat; the
// landed rays scaled so the brightest pixel reads 4095 (12 bits, no noise).
ImageF traced_12bit(const optics::CameraModel& cam, const optics::MicrolensArray& lenses,
                    const std::vector<sim::Point3>& positions, std::uint64_t seed) {
  ImageF image = sim::render(cam, lenses, positions, sim::RenderOptions{}, seed).rays;
  float peak = 0;
  for (float v : image.pixels) peak = std::max(peak, v);
  for (float& v : image.pixels) v = std::round(v / peak * 4095.f);
  return image;
}

Grid3 grid_of(int nx, int ny, int nz, double voxel_mm, double depth_mm) {
  Grid3 g;
  g.shape = {nx, ny, nz};
  g.spacing_mm = {voxel_mm, voxel_mm, depth_mm / nz};
  g.origin_mm = {-0.5 * (nx - 1) * voxel_mm, -0.5 * (ny - 1) * voxel_mm, -0.5 * (nz - 1) * depth_mm / nz};
  return g;
}

// `reuse`: after the first reconstruction (in a new recon::MartWorkspace), the same image again in
// that workspace and once more without one, to compare a first frame with the steady state.
void paper_scale(const std::string& source_dir, bool small, double ppm, int iterations, float threshold_counts,
                 double dark_cutoff, std::size_t count_override = 0, double mu = 0.5, bool accelerate = false,
                 double sensor_blur_mm = 0.0, recon::MartStart start = recon::MartStart::mlos, bool reuse = false) {
  const auto cam = optics::load_camera_file(
      source_dir + (small ? "/systemd/config/camera-small.yaml" : "/systemd/config/camera-fahringer2015.yaml"));
  const auto lenses = optics::MicrolensArray::from_lattice(optics::Lattice::nominal(cam));
  // The paper's 500-particle box: 30 x 20 x 20 mm in 300 x 200 x 200 voxels of 0.1 mm; or the sec
  // 5.4 small camera's 6 x 6 x 20 mm in 60 x 60 x 200 voxels.
  const Grid3 g = small ? grid_of(60, 60, 200, 0.1, 20.0) : grid_of(300, 200, 200, 0.1, 20.0);
  auto t = Clock::now();
  double c = cpu_seconds();
  ImageF white = calib::geometric_white_image(cam, lenses);
  std::printf("bench=recon_paper phase=white_image seconds=%.3f cpu_s=%.3f\n", since(t), cpu_seconds() - c);
  t = Clock::now();
  c = cpu_seconds();
  const recon::WeightingOperator op(cam, lenses, g, std::move(white));
  std::printf("bench=recon_paper phase=tables_and_normalisers seconds=%.3f cpu_s=%.3f\n", since(t), cpu_seconds() - c);

  // Particles filling the box at `ppm` (counted over the field of view, as the paper does).
  const sim::Box box = small ? sim::Box{{-3, -3, -10}, {3, 3, 10}} : sim::Box{{-15, -10, -10}, {15, 10, 10}};
  const std::size_t count = count_override ? count_override : sim::particle_count_from_ppm(cam, box, ppm);
  const auto positions = sim::random_particles(box, count, 1);
  t = Clock::now();
  const ImageF image = traced_12bit(cam, lenses, positions, 1);
  std::printf("bench=recon_paper phase=render_image seconds=%.3f\n", since(t));
  std::size_t lit = 0;
  for (float v : image.pixels) lit += v > 0;

  recon::MartSettings s;
  s.iterations = iterations;
  s.mu = mu;
  s.accelerate = accelerate;
  s.sensor_blur_sigma_mm = sensor_blur_mm;
  s.start = start;
  s.noise_threshold = threshold_counts;
  s.dark_weight_cutoff = dark_cutoff;
  recon::MartWorkspace workspace;
  t = Clock::now();
  c = cpu_seconds();
  long faults = minor_faults();
  const recon::MartResult r = recon::reconstruct(op, image, s, workspace, [](const recon::IterationReport& it) {
    std::printf("bench=recon_paper phase=iteration n=%d seconds=%.3f residual=%.4f\n", it.iteration, it.seconds,
                it.residual);
  });
  const double t_mart = since(t), c_mart = cpu_seconds() - c;
  const long faults_mart = minor_faults() - faults;
  double iter_total = 0;
  for (const auto& it : r.iterations) iter_total += it.seconds;
  const recon::SkipReport& k = r.skipped;
  const std::uint64_t hash = bench::bits_hash(r.volume.data);
  std::printf(
      "bench=recon_paper particles=%zu ppm=%.2f lit_pixel_fraction=%.4f threshold_counts=%.1f dark_cutoff=%.2f "
      "iterations=%d mu=%.2f accelerate=%d sensor_blur_mm=%.4f start=%s\n",
      count, ppm, double(lit) / double(image.size()), double(s.noise_threshold), dark_cutoff, iterations, mu,
      int(accelerate), sensor_blur_mm, std::string(recon::name_of(start)).c_str());
  std::printf("bench=recon_paper phase=active_set_and_mlos seconds=%.3f select=%.3f active_set=%.3f start=%.3f\n",
              r.setup_seconds, r.select_seconds, r.active_set_seconds, r.start_seconds);
  std::printf("bench=recon_paper phase=iterations seconds=%.3f per_iteration=%.3f\n", iter_total,
              iter_total / double(std::max<std::size_t>(1, r.iterations.size())));
  std::printf(
      "bench=recon_paper phase=reconstruct_total seconds=%.3f cpu_s=%.3f final_residual=%.4f volume_hash=%016llx\n",
      t_mart, c_mart, r.final_residual.value(), static_cast<unsigned long long>(hash));
  std::printf(
      "bench=recon_paper voxels=%zu active=%zu skipped_fraction=%.4f dark=%zu unseen=%zu slices_empty=%d "
      "dark_pixels=%zu\n",
      k.voxels, k.voxels_active, k.fraction_skipped(), k.voxels_dark, k.voxels_unseen, k.slices_empty, k.dark_pixels);
  if (reuse) {
    // The first frame above against the steady state of a caller that keeps its workspace (the
    // same image again: the same bits; the third frame in it, as a run settles: the active set's
    // two voxel lists take turns, so the second frame still allocates one of them), and a frame
    // without one (the process is warm, so this separates the workspace's gain from the first
    // call's other costs).
    auto frame = [&](const char* variant, recon::MartWorkspace* ws) {
      const auto t0 = Clock::now();
      const double c0 = cpu_seconds();
      const long f0 = minor_faults();
      const recon::MartResult again = ws ? recon::reconstruct(op, image, s, *ws) : recon::reconstruct(op, image, s);
      const double wall = since(t0), cpu = cpu_seconds() - c0;
      std::printf(
          "bench=recon_reuse variant=%s seconds=%.3f cpu_s=%.3f setup_s=%.3f minor_faults=%ld volume_hash=%016llx\n",
          variant, wall, cpu, again.setup_seconds, minor_faults() - f0,
          static_cast<unsigned long long>(bench::bits_hash(again.volume.data)));
      return std::array<double, 2>{wall, cpu};
    };
    std::printf(
        "bench=recon_reuse variant=first seconds=%.3f cpu_s=%.3f setup_s=%.3f minor_faults=%ld volume_hash=%016llx "
        "workspace_mb=%.0f\n",
        t_mart, c_mart, r.setup_seconds, faults_mart, static_cast<unsigned long long>(hash),
        double(workspace.bytes()) / (1 << 20));
    frame("reused_second", &workspace);
    const auto reused = frame("reused", &workspace);
    const auto fresh = frame("fresh_again", nullptr);
    std::printf(
        "bench=recon_reuse reused_over_first_wall=%.3f reused_over_first_cpu=%.3f "
        "reused_over_fresh_again_wall=%.3f reused_over_fresh_again_cpu=%.3f\n",
        reused[0] / t_mart, reused[1] / c_mart, reused[0] / fresh[0], reused[1] / fresh[1]);
  }
  const Volume exact = sim::render_exact_volume(g, positions);
  std::printf("bench=recon_paper quality_q_star=%.4f\n", recon::quality_factor(r.volume, exact));
  // Fig 22: per-particle position errors, the brightest voxel searched within 3 x 3 x 15 voxels of
  // the true position; two estimators of its centre: the log-parabola through the peak's own rows
  // (fit_particle) and the moments of the 3 x 3 x 31 voxels around it (fit_particle_moments).
  // Besides abs error mean / sd: the signed depth error's least-squares slope against depth, in
  // per cent of depth (negative: particles reconstructed nearer the focal plane than they are).
  auto report = [&](const char* estimator, auto&& fit_of) {
    std::vector<double> ex, ez, z_true, dz;
    for (const auto& p : positions) {
      const auto fit = fit_of(p);
      if (!fit) continue;
      ex.push_back(std::abs(fit->position_mm[0] - p[0]) / g.spacing_mm[0]);
      ez.push_back(std::abs(fit->position_mm[2] - p[2]) / g.spacing_mm[2]);
      z_true.push_back(p[2]);
      dz.push_back(fit->position_mm[2] - p[2]);
    }
    auto mean_sd = [](const std::vector<double>& v) {
      double m = 0, q = 0;
      for (double x : v) m += x;
      m /= double(std::max<std::size_t>(1, v.size()));
      for (double x : v) q += (x - m) * (x - m);
      return std::array<double, 2>{m, std::sqrt(q / double(std::max<std::size_t>(1, v.size())))};
    };
    const auto mx = mean_sd(ex), mz = mean_sd(ez), zt = mean_sd(z_true), d = mean_sd(dz);
    double cov = 0;
    for (std::size_t i = 0; i < dz.size(); ++i) cov += (z_true[i] - zt[0]) * (dz[i] - d[0]);
    const double slope = zt[1] > 0 ? cov / double(dz.size()) / (zt[1] * zt[1]) : 0.0;
    std::printf(
        "bench=recon_paper fit=%s fitted=%zu particles=%zu abs_x_err_vox_mean=%.3f "
        "abs_x_err_vox_sd=%.3f abs_z_err_vox_mean=%.3f abs_z_err_vox_sd=%.3f "
        "depth_error_slope_percent=%.2f\n",
        estimator, ex.size(), positions.size(), mx[0], mx[1], mz[0], mz[1], 100 * slope);
    // The signed depth error by depth, 2 mm bins: where its change across bins is not zero, two
    // particles a bin apart come out nearer or farther apart in depth than they are, and a depth
    // displacement there is measured short or long by that much.
    std::printf("bench=recon_paper_depth fit=%s", estimator);
    for (int bin = -7; bin < 7; ++bin) {
      double sum = 0;
      int n = 0;
      for (std::size_t i = 0; i < dz.size(); ++i)
        if (z_true[i] >= 2.0 * bin && z_true[i] < 2.0 * (bin + 1)) sum += dz[i], ++n;
      std::printf(" dz_mm_at_%+d=%.3f n_at_%+d=%d", 2 * bin + 1, n ? sum / n : 0.0, 2 * bin + 1, n);
    }
    std::printf("\n");
  };
  report("peak_rows", [&](const sim::Point3& p) { return recon::fit_particle(r.volume, p, {3, 3, 15}); });
  report("moments", [&](const sim::Point3& p) { return recon::fit_particle_moments(r.volume, p, {3, 3, 15}); });
  std::printf("bench=recon_paper peak_rss_gb=%.3f\n", bench::peak_rss_gb());
}

void mid_size(const std::string& source_dir) {
  const auto cam = optics::load_camera_file(source_dir + "/systemd/config/camera-small.yaml");
  const auto lenses = optics::MicrolensArray::from_lattice(optics::Lattice::nominal(cam));
  const Grid3 g = grid_of(32, 32, 32, 0.125, 10.0);
  const recon::WeightingOperator op(cam, lenses, g, calib::geometric_white_image(cam, lenses));
  auto t = Clock::now();
  const recon::SparseMatrix w = recon::build_explicit_matrix(op);
  const double t_build = since(t);
  std::vector<float> x(g.count()), img(op.pixel_count()), back(g.count());
  std::mt19937 rng(3);
  std::uniform_real_distribution<float> u(0.f, 1.f);
  for (float& v : x) v = u(rng);
  auto median = [](auto f) {
    std::vector<double> times;
    for (int k = 0; k < 5; ++k) {
      const auto t0 = Clock::now();
      f();
      times.push_back(since(t0));
    }
    std::sort(times.begin(), times.end());
    return times[2];
  };
  // The voxel set (columns, bands) is built once per reconstruction, not per pass.
  t = Clock::now();
  const recon::ActiveSet all = recon::ActiveSet::all(op);
  const double t_set = since(t);
  const double ex_p = median([&] { w.multiply(x, img); });
  const double ex_b = median([&] { w.multiply_transpose(img, back); });
  const double mf_p = median([&] { all.project(op, x, img); });
  const double mf_b = median([&] { all.back_project(op, img, back); });
  std::printf("bench=recon_mid voxels=%zu nonzeros=%zu explicit_bytes=%zu build_s=%.3f active_set_s=%.4f\n", g.count(),
              w.nonzeros(), w.nonzeros() * 8 + w.row_start.size() * 8, t_build, t_set);
  std::printf("bench=recon_mid op=project variant=explicit median_s=%.4f\n", ex_p);
  std::printf("bench=recon_mid op=project variant=matrix_free median_s=%.4f ratio=%.2f\n", mf_p, ex_p / mf_p);
  std::printf("bench=recon_mid op=back_project variant=explicit median_s=%.4f\n", ex_b);
  std::printf("bench=recon_mid op=back_project variant=matrix_free median_s=%.4f ratio=%.2f\n", mf_b, ex_b / mf_b);
}

// The value-adaptive active set side by side on one image: pruning off, exact zeros only, and
// relative thresholds; each variant's time (wall, CPU), voxel updates skipped over the
// iterations, Q*, the moments fit's errors and the volume's hash; first in a fresh workspace (with
// the memory it faulted in: fresh_memory_gb), then again in the kept one (kept_*, with the set-up's
// parts). `small`: the sec 5.4 camera.
// `bench_recon prune [paper|small] [ppm] [iterations] [mu] [nesterov|none] [variants, e.g. off,1e-2]`.
void prune_sweep(const std::string& source_dir, bool small, double ppm, int iterations, double mu, bool accelerate,
                 const std::string& only) {
  const auto cam = optics::load_camera_file(
      source_dir + (small ? "/systemd/config/camera-small.yaml" : "/systemd/config/camera-fahringer2015.yaml"));
  const calib::LoadedCalibration nominal = calib::nominal_calibration(cam);
  const Grid3 g = small ? grid_of(60, 60, 200, 0.1, 20.0) : grid_of(300, 200, 200, 0.1, 20.0);
  const recon::WeightingOperator op(cam, nominal.lenses, g, nominal.white_correction);
  const sim::Box box = small ? sim::Box{{-3, -3, -10}, {3, 3, 10}} : sim::Box{{-15, -10, -10}, {15, 10, 10}};
  const auto positions = sim::random_particles(box, sim::particle_count_from_ppm(cam, box, ppm), 1);
  const ImageF image = traced_12bit(cam, nominal.lenses, positions, 1);
  const Volume exact = sim::render_exact_volume(g, positions);
  struct Variant {
    const char* name;
    bool prune;
    double threshold;
    recon::PruneScope scope = recon::PruneScope::volume;
    double local = 0.0;  // MartSettings::prune_local_threshold
  };
  std::uint64_t reference = 0;
  for (const Variant& v : {Variant{"off", false, 0.0}, Variant{"zeros", true, 0.0}, Variant{"1e-4", true, 1e-4},
                           Variant{"1e-3", true, 1e-3}, Variant{"3e-3", true, 3e-3}, Variant{"1e-2", true, 1e-2},
                           Variant{"slice-1e-2", true, 1e-2, recon::PruneScope::slice},
                           Variant{"slice-3e-2", true, 3e-2, recon::PruneScope::slice},
                           Variant{"slice-1e-2-local-5e-2", true, 1e-2, recon::PruneScope::slice, 5e-2},
                           Variant{"slice-1e-2-local-1e-1", true, 1e-2, recon::PruneScope::slice, 1e-1}}) {
    if (!only.empty() && ("," + only + ",").find("," + std::string(v.name) + ",") == std::string::npos) continue;
    recon::MartSettings s;
    s.iterations = iterations;
    s.mu = mu;
    s.accelerate = accelerate;
    s.final_residual = false;
    s.prune = v.prune;
    s.prune_threshold = v.threshold;
    s.prune_scope = v.scope;
    s.prune_local_threshold = v.local;
    std::string live, seconds, work;
    // Each variant's first frame in a fresh workspace (a one-shot call's), then the same frame
    // again in it (a run's steady state, which keeps its workspace): the same bits.
    recon::MartWorkspace workspace;
    const double rss_before = bench::rss_gb();
    const auto t = Clock::now();
    const double c = cpu_seconds();
    const recon::MartResult r = recon::reconstruct(op, image, s, workspace, [&](const recon::IterationReport& it) {
      live += (live.empty() ? "" : ",") + std::to_string(it.live_voxels);
      work += (work.empty() ? "" : ",") + std::to_string(it.work_fraction).substr(0, 5);
      char t[32];
      std::snprintf(t, sizeof t, "%s%.2f", seconds.empty() ? "" : ",", it.seconds);
      seconds += t;
    });
    const double wall = since(t), cpu = cpu_seconds() - c;
    const double fresh_gb = bench::rss_gb() - rss_before;  // memory the first frame faulted in
    const std::uint64_t hash = bench::bits_hash(r.volume.data);
    if (!v.prune) reference = hash;
    const auto t_kept = Clock::now();
    const double c_kept = cpu_seconds();
    const recon::MartResult kept = recon::reconstruct(op, image, s, workspace);
    const double wall_kept = since(t_kept), cpu_kept = cpu_seconds() - c_kept;
    const bool same_kept = bench::bits_hash(kept.volume.data) == hash;
    double ex = 0, ez = 0;
    std::size_t fitted = 0;
    for (const auto& p : positions) {
      const auto fit = recon::fit_particle_moments(r.volume, p, {3, 3, 15});
      if (!fit) continue;
      ex += std::abs(fit->position_mm[0] - p[0]) / g.spacing_mm[0];
      ez += std::abs(fit->position_mm[2] - p[2]) / g.spacing_mm[2];
      ++fitted;
    }
    std::printf(
        "bench=recon_prune case=%s variant=%s iterations=%d mu=%.2f accelerate=%d seconds=%.3f cpu_s=%.3f "
        "setup_s=%.3f select_s=%.3f active_set_s=%.3f start_s=%.3f prune_s=%.3f iteration_s=%s skipped=%.4f "
        "updates_skipped=%.4f pruned=%zu "
        "live_per_iteration=%s work_per_iteration=%s work_pruned=%.4f "
        "q_star=%.4f moments_abs_x_vox=%.3f abs_z_vox=%.3f fitted=%zu volume_hash=%016llx same_as_off=%d "
        "fresh_memory_gb=%.3f kept_seconds=%.3f kept_cpu_s=%.3f kept_setup_s=%.3f kept_select_s=%.3f "
        "kept_active_set_s=%.3f kept_start_s=%.3f kept_same_bits=%d\n",
        small ? "small" : "paper", v.name, iterations, mu, int(accelerate), wall, cpu, r.setup_seconds,
        r.select_seconds, r.active_set_seconds, r.start_seconds, r.prune_seconds, seconds.c_str(),
        r.skipped.fraction_skipped(), r.skipped.fraction_updates_skipped(), r.skipped.voxels_pruned, live.c_str(),
        work.c_str(), r.skipped.fraction_work_pruned(), recon::quality_factor(r.volume, exact),
        ex / double(std::max<std::size_t>(1, fitted)), ez / double(std::max<std::size_t>(1, fitted)), fitted,
        static_cast<unsigned long long>(hash), int(hash == reference), fresh_gb, wall_kept, cpu_kept,
        kept.setup_seconds, kept.select_seconds, kept.active_set_seconds, kept.start_seconds, int(same_kept));
  }
  std::printf("bench=recon_prune peak_rss_gb=%.3f\n", bench::peak_rss_gb());
}

}  // namespace

// The paper's accuracy figures on the sec 5.4 small camera: fig 21 (single particles along the
// axis, 1 mm apart), fig 23b (Q* against iterations at 0.5 ppm), fig 23c (Q* against density).
void figures(const std::string& source_dir, double dark_cutoff) {
  const auto cam = optics::load_camera_file(source_dir + "/systemd/config/camera-small.yaml");
  const auto lenses = optics::MicrolensArray::from_lattice(optics::Lattice::nominal(cam));
  {
    // 6.125 x 6.125 x 20 mm in 0.125 mm voxels (the paper: 50 x 50 x 402 over 50 mm).
    Grid3 g;
    g.shape = {49, 49, 161};
    g.spacing_mm = {0.125, 0.125, 0.125};
    g.origin_mm = {-3.0, -3.0, -10.0};
    const recon::WeightingOperator op(cam, lenses, g, calib::geometric_white_image(cam, lenses));
    for (int k = -9; k <= 9; ++k) {
      const std::array<double, 3> p{0.0, 0.0, double(k)};  // on a voxel centre, as the paper
      // 10^5 rays (core/sim, diffraction on): enough that Monte Carlo noise does not move the fit.
      sim::RenderOptions ro;
      ro.rays_per_particle = 100000;
      const ImageF image = sim::render(cam, lenses, std::vector<sim::Point3>{p}, ro, 21).rays;
      recon::MartSettings s;
      s.dark_weight_cutoff = dark_cutoff;
      const recon::MartResult r = recon::reconstruct(op, image, s);
      const auto fit = recon::fit_particle(r.volume, p, {3, 3, 40});
      if (!fit) {
        std::printf("bench=recon_fig21 z_mm=%.1f found=0\n", p[2]);
        continue;
      }
      std::printf("bench=recon_fig21 z_mm=%.1f lateral_err_vox=%.3f depth_err_vox=%.3f active=%zu\n", p[2],
                  std::hypot(fit->position_mm[0] - p[0], fit->position_mm[1] - p[1]) / 0.125,
                  (fit->position_mm[2] - p[2]) / 0.125, r.skipped.voxels_active);
    }
  }
  const Grid3 g = grid_of(60, 60, 200, 0.1, 20.0);
  const recon::WeightingOperator op(cam, lenses, g, calib::geometric_white_image(cam, lenses));
  const sim::Box box{{-3, -3, -10}, {3, 3, 10}};
  auto run = [&](double ppm, int iterations, bool converged = false) {
    const auto positions = sim::random_particles(box, sim::particle_count_from_ppm(cam, box, ppm), 7);
    const ImageF image = traced_12bit(cam, lenses, positions, 7);
    recon::MartSettings s;
    s.iterations = iterations;
    s.dark_weight_cutoff = dark_cutoff;
    if (converged) {  // fig 22's accurate setting: accelerated at mu 1 with the diffraction modelled
      s.mu = 1.0;
      s.accelerate = true;
      s.sensor_blur_sigma_mm = sim::RenderOptions{}.diffraction_sigma_mm;
    }
    const recon::MartResult r = recon::reconstruct(op, image, s);
    return std::array<double, 3>{recon::quality_factor(r.volume, sim::render_exact_volume(g, positions)),
                                 r.skipped.fraction_skipped(), r.final_residual.value()};
  };
  for (int it : {1, 2, 5, 10, 20}) {
    const auto q = run(0.5, it);
    std::printf("bench=recon_fig23b ppm=0.5 iterations=%d q_star=%.4f skipped=%.4f residual=%.4f\n", it, q[0], q[1],
                q[2]);
  }
  for (double ppm : {0.1, 0.5, 1.0, 2.0, 3.0}) {
    const auto q = run(ppm, 5);
    std::printf("bench=recon_fig23c ppm=%.1f iterations=5 q_star=%.4f skipped=%.4f residual=%.4f\n", ppm, q[0], q[1],
                q[2]);
  }
  for (double ppm : {0.1, 0.5, 1.0, 2.0, 3.0}) {
    const auto q = run(ppm, 20, true);
    std::printf(
        "bench=recon_fig23c ppm=%.1f iterations=20 mu=1 accelerate=1 sensor_blur_mm=%.4f q_star=%.4f "
        "skipped=%.4f residual=%.4f\n",
        ppm, sim::RenderOptions{}.diffraction_sigma_mm, q[0], q[1], q[2]);
  }
}

int main(int argc, char** argv) {
  std::setvbuf(stdout, nullptr, _IOLBF, 0);  // lines appear as they are measured
  std::string which = argc > 1 ? argv[1] : "all";
  const std::string source_dir = PLENOPIV_SOURCE_DIR;
  if (which == "prune") {
    const bool small = argc > 2 && std::string(argv[2]) == "small";
    prune_sweep(source_dir, small, argc > 3 ? std::stod(argv[3]) : 0.5, argc > 4 ? std::stoi(argv[4]) : 8,
                argc > 5 ? std::stod(argv[5]) : 1.0, !(argc > 6 && std::string(argv[6]) == "none"),
                argc > 7 ? argv[7] : "");
    return 0;
  }
  const double ppm = argc > 2 ? std::stod(argv[2]) : 0.5;
  const float threshold = argc > 3 ? std::stof(argv[3]) : 0.f;
  const double cutoff = argc > 4 ? std::stod(argv[4]) : 0.9;
  const int iterations = which != "fig22" && argc > 5 ? std::stoi(argv[5]) : 5;  // fig22 reads its own
  if (which == "mid" || which == "all") mid_size(source_dir);
  if (which == "figures") figures(source_dir, argc > 2 ? std::stod(argv[2]) : 0.9);
  // Fig 22: 500 particles in the paper-scale box;
  // `fig22 [cutoff] [iterations] [mu] [nesterov|none] [sensor blur sigma, mm]`.
  if (which == "fig22")
    paper_scale(source_dir, false, 0, argc > 3 ? std::stoi(argv[3]) : 5, 0.f, argc > 2 ? std::stod(argv[2]) : 0.9, 500,
                argc > 4 ? std::stod(argv[4]) : 0.5, argc > 5 && std::string(argv[5]) == "nesterov",
                argc > 6 ? std::stod(argv[6]) : 0.0);
  if (which == "small") paper_scale(source_dir, true, ppm, iterations, threshold, cutoff);

  // `paper [ppm] [threshold] [cutoff] [iterations] [sensor blur sigma, mm] [mlos|ones]`, and the
  // first frame against a kept workspace (bench=recon_reuse).
  if (which == "paper" || which == "all")
    paper_scale(source_dir, false, ppm, iterations, threshold, cutoff, 0, 0.5, false,
                argc > 6 ? std::stod(argv[6]) : 0.0,
                argc > 7 ? recon::mart_start_named(argv[7], "bench_recon paper: start") : recon::MartStart::mlos,
                which == "paper");
  return 0;
}
