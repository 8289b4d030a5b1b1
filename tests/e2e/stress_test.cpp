// Numerical stress: many randomised tiny frame pairs (seeding 0-3 ppm, depth ranges, noise, zero
// and saturated frames, particles all outside, one particle, extreme mu and iterations, the black
// level taken off or not) through process_pair -> no crash, finite outputs, identical at 1 and 2
// threads; bad images refused.
#include <gtest/gtest.h>
#include <tbb/global_control.h>

#include <cmath>
#include <limits>
#include <map>
#include <memory>
#include <random>
#include <span>

#include "core/base/errors.hpp"
#include "core/calib/nominal_calibration.hpp"
#include "core/optics/camera_file.hpp"
#include "core/process/black_level.hpp"
#include "core/process/process.hpp"
#include "core/sim/particles.hpp"
#include "core/sim/render.hpp"
#include "tests/support/same_bits.hpp"

#ifndef PLENOPIV_STRESS_CASES
#define PLENOPIV_STRESS_CASES 250
#endif
// The long form is another suite name: ctest keys labels by test name.
#ifndef PLENOPIV_STRESS_SUITE
#define PLENOPIV_STRESS_SUITE Stress
#endif

namespace plenopiv::process {
namespace {

using testing_support::same_bits;

// 170 x 170 pixels behind 10 x 10 lenses (the small camera's optics): a 1.25 mm field of view.
const char* kTinyCamera = R"(
sensor:    {width_px: 170, height_px: 170, pixel_pitch_mm: 0.0074}
microlens: {pitch_mm: 0.125, focal_length_mm: 0.5, count_x: 10, count_y: 10, layout: rect}
main_lens: {focal_length_mm: 50, f_number: 2, magnification: -1}
)";

struct Fixture {
  optics::CameraModel camera = optics::parse_camera_yaml(kTinyCamera, "tiny camera");
  optics::MicrolensArray lenses = optics::MicrolensArray::from_lattice(optics::Lattice::nominal(camera));
  ImageF white = calib::geometric_white_image(camera, lenses);
  // One operator per depth extent (the expensive part, shared by the cases).
  std::map<int, std::unique_ptr<recon::WeightingOperator>> operators;

  const recon::WeightingOperator& op(const Grid3& g, int key) {
    auto& p = operators[key];
    if (!p) p = std::make_unique<recon::WeightingOperator>(camera, lenses, g, white);
    return *p;
  }
};

Fixture& fixture() {
  static Fixture f;
  return f;
}

// Depth extents of the reconstruction box, mm: shallow, deep, off-centre.
constexpr double kDepths[3][2] = {{-0.6, 0.6}, {-1.2, 1.2}, {0.2, 1.4}};

struct Case {
  ProcessSettings settings;
  int depth = 0;
  ImageF a, b;
  std::string description;
};

ImageF to_float(const ImageU16& u) {
  ImageF f(u.width, u.height);
  for (std::size_t i = 0; i < u.size(); ++i) f.pixels[i] = u.pixels[i];
  return f;
}

Case make_case(std::uint64_t index) {
  std::mt19937_64 rng(index * 0x9E3779B97F4A7C15ull + 1);
  auto uniform = [&](double lo, double hi) { return std::uniform_real_distribution<double>(lo, hi)(rng); };
  auto pick = [&](int n) { return int(std::uniform_int_distribution<int>(0, n - 1)(rng)); };
  Case c;
  c.depth = pick(3);
  c.settings.grid =
      grid_for_extent({-0.6, -0.6, kDepths[c.depth][0]}, {0.6, 0.6, kDepths[c.depth][1]}, {0.1, 0.1, 0.1}, "stress");
  const double mus[] = {1e-4, 0.01, 0.5, 1.0};
  const int iterations[] = {1, 2, 5, 30};
  c.settings.mart.mu = mus[pick(4)];
  c.settings.mart.iterations = iterations[pick(4)];
  c.settings.mart.start = pick(2) ? recon::MartStart::mlos : recon::MartStart::ones;
  c.settings.mart.noise_threshold = float(pick(3) * 2);
  c.settings.correlation.passes = {{{8, 8, 8}, 50}, {{6, 6, 6}, 50}};
  c.settings.correlation.dt_s = 1e-4;

  const auto& camera = fixture().camera;
  const int mode = pick(6);  // 0-2 seeded, 3 one particle, 4 all outside the volume, 5 zero/saturated
  const double ppm = uniform(0, 3);
  sim::Box box{{-0.7, -0.7, kDepths[c.depth][0]}, {0.7, 0.7, kDepths[c.depth][1]}};
  std::size_t count = sim::particle_count_from_ppm(camera, box, ppm);
  if (mode == 3) count = 1;
  if (mode == 4) box = {{-0.7, -0.7, 3.0}, {0.7, 0.7, 4.0}};  // beyond the deepest box
  const auto pa = sim::random_particles(box, count, index);
  const sim::Point3 shift{uniform(-0.1, 0.1), uniform(-0.1, 0.1), uniform(-0.1, 0.1)};
  std::vector<sim::Point3> pb = pa;
  for (auto& p : pb)
    for (int k = 0; k < 3; ++k) p[std::size_t(k)] += shift[std::size_t(k)];

  sim::RenderOptions ro;
  ro.rays_per_particle = 300;
  ro.sensor.shot_noise = pick(2) == 1;
  ro.sensor.read_noise_electrons = uniform(0, 3);
  ro.sensor.dark_offset_dn = double(pick(3));
  ro.sensor.electrons_per_ray = uniform(1, 200);  // bright enough to saturate some pixels
  const auto& lenses = fixture().lenses;
  c.a = to_float(sim::render(camera, lenses, pa, ro, 2 * index + 1).image);
  c.b = to_float(sim::render(camera, lenses, pb, ro, 2 * index + 2).image);
  if (mode == 5) {
    const float fill = pick(2) ? 0.f : 65535.f;
    std::fill(c.a.pixels.begin(), c.a.pixels.end(), fill);
    if (pick(2)) std::fill(c.b.pixels.begin(), c.b.pixels.end(), fill);
  }
  // Drawn last, so that the draws above (and the cases they made before these knobs) stay as they were.
  c.settings.mart.accelerate = pick(2) == 1;
  const double floors[] = {0, 0, 4, 100};  // none, process.yaml's, the largest allowed
  c.settings.correlation.intensity_threshold_of_mean = floors[pick(4)];
  const int margins[] = {0, 2, 6};  // none, some, the second pass's whole window depth (the largest allowed)
  c.settings.correlation.passes[1].depth_margin = margins[pick(3)];
  const int smoothing[] = {0, 1, 4};  // none, process.yaml's, the most allowed
  c.settings.correlation.final_smoothing = smoothing[pick(3)];
  const int depth_passes[] = {0, 4, 8};  // none, the shipped configs', the most allowed
  c.settings.correlation.depth_prefilter = depth_passes[pick(3)];
  const double prune_thresholds[] = {0, 0, 1e-2, 0.5};  // exact zeros (the default), a small and a large cut
  c.settings.mart.prune_threshold = prune_thresholds[pick(4)];
  c.settings.mart.prune_scope = pick(2) ? recon::PruneScope::slice : recon::PruneScope::volume;
  const int reaches[] = {0, 0, 2, recon::kMaxPruneDepthReach};  // the threshold alone, a particle's ends, the most
  c.settings.mart.prune_depth_reach = reaches[pick(4)];
  c.settings.correlation.early_interpolation = pick(2) ? piv::Interpolation::cubic : piv::Interpolation::sinc;
  // Off (the default), the shipped configs', phase only, and a power off the exact square roots' paths.
  const double whitening[] = {0, 0.5, 1, 0.3};
  c.settings.correlation.spectral_whitening = whitening[pick(4)];
  // The shipped peak, and the narrowest and widest allowed.
  const std::array<double, 3> peak_sigmas[] = {{1, 1, 2}, {0.5, 0.5, 0.5}, {8, 8, 8}};
  c.settings.correlation.whitened_peak_sigma_voxel = peak_sigmas[pick(3)];
  const int strides[] = {1, 2, 4};  // every node (the default), run-paper.yaml's, the largest allowed
  c.settings.correlation.uncertainty_stride = strides[pick(3)];
  // The final pass's peak at the predictor first, where its (final) pass has no depth margin.
  const bool near = pick(2) == 1 && c.settings.correlation.passes[1].depth_margin == 0;
  c.settings.correlation.final_peak_search =
      near ? piv::FinalPeakSearch::near_predictor : piv::FinalPeakSearch::all_shifts;
  // Each frame's black level taken off as PairProcessor does (the frames carry up to 2 counts of
  // pedestal; a zero or saturated frame is taken off whole), or left on.
  c.settings.black_level = pick(2) ? BlackLevel::between_images : BlackLevel::none;
  BlackLevels levels[2];
  if (c.settings.black_level == BlackLevel::between_images) {
    const BlackLevelMeter meter(fixture().white);
    levels[0] = meter.measure(c.a);
    levels[1] = meter.measure(c.b);
    subtract_black_level(c.a, levels[0]);
    subtract_black_level(c.b, levels[1]);
  }
  // The cut against each voxel's neighbourhood: off (the default), run-paper.yaml's, a large one.
  const double local_thresholds[] = {0, 0, 5e-2, 0.5};
  c.settings.mart.prune_local_threshold = local_thresholds[pick(4)];
  // The MLOS start: the geometric mean (the default), raised to 3, to the most allowed (the start
  // of ones takes no power).
  const double mlos_powers[] = {1, 1, 3, recon::kMaxMlosPower};
  const double mlos_power = mlos_powers[pick(4)];
  c.settings.mart.mlos_power = c.settings.mart.start == recon::MartStart::mlos ? mlos_power : 1.0;
  const auto& sigma = c.settings.correlation.whitened_peak_sigma_voxel;
  c.description =
      "case " + std::to_string(index) + ": mode " + std::to_string(mode) + ", " + std::to_string(count) +
      " particles, mu " + std::to_string(c.settings.mart.mu) + ", " + std::to_string(c.settings.mart.iterations) +
      " iterations" + (c.settings.mart.accelerate ? " accelerated" : "") + ", intensity floor " +
      std::to_string(c.settings.correlation.intensity_threshold_of_mean) + "x the mean, depth margin " +
      std::to_string(c.settings.correlation.passes[1].depth_margin) + ", final smoothing " +
      std::to_string(c.settings.correlation.final_smoothing) + ", depth prefilter " +
      std::to_string(c.settings.correlation.depth_prefilter) + ", prune threshold " +
      std::to_string(c.settings.mart.prune_threshold) + " of the " +
      (c.settings.mart.prune_scope == recon::PruneScope::slice ? "slice's" : "volume's") + " peak, depth reach " +
      std::to_string(c.settings.mart.prune_depth_reach) + ", neighbourhood cut " +
      std::to_string(c.settings.mart.prune_local_threshold) + ", MLOS start to the power " +
      std::to_string(c.settings.mart.mlos_power) + ", early interpolation " +
      (c.settings.correlation.early_interpolation == piv::Interpolation::cubic ? "cubic" : "sinc") +
      ", spectral whitening " + std::to_string(c.settings.correlation.spectral_whitening) + " with a peak of " +
      std::to_string(sigma[0]) + " x " + std::to_string(sigma[1]) + " x " + std::to_string(sigma[2]) +
      " voxels, uncertainty every " + std::to_string(c.settings.correlation.uncertainty_stride) + " nodes, " +
      (near ? "final peaks at the predictor first" : "final peaks over all shifts") + ", black level " +
      std::string(name_of(c.settings.black_level)) + " (" + levels[0].text() + ", " + levels[1].text() +
      " counts), depth " + std::to_string(c.depth);
  return c;
}

bool all_finite(std::span<const float> v) {
  for (float x : v)
    if (!std::isfinite(x)) return false;
  return true;
}

PairResult run_at(int threads, const Case& c) {
  tbb::global_control limit(tbb::global_control::max_allowed_parallelism, std::size_t(threads));
  return process_pair(fixture().op(c.settings.reconstruction_grid(), c.depth), c.a, c.b, c.settings);
}

TEST(PLENOPIV_STRESS_SUITE, RandomisedPairsAreFiniteAndThreadIndependent) {
  const int cases = PLENOPIV_STRESS_CASES;
  int with_valid = 0;
  for (int i = 0; i < cases; ++i) {
    const Case c = make_case(std::uint64_t(i));
    SCOPED_TRACE(c.description);
    PairResult one, two;
    ASSERT_NO_THROW(one = run_at(1, c));
    ASSERT_NO_THROW(two = run_at(2, c));
    for (const Volume* v : {&one.volume_a, &one.volume_b}) {
      ASSERT_TRUE(all_finite(v->data));
      for (float x : v->data) ASSERT_GE(x, 0.f);
    }
    const VectorField& f = one.correlation.field;
    ASSERT_TRUE(all_finite(f.dx_mm));
    ASSERT_TRUE(all_finite(f.dy_mm));
    ASSERT_TRUE(all_finite(f.dz_mm));
    // The peak ratio: finite, or NaN where the final pass found the peak at the predictor (no
    // second peak to compare).
    const bool near = c.settings.correlation.final_peak_search == piv::FinalPeakSearch::near_predictor;
    for (float r : f.peak_ratio) ASSERT_TRUE(std::isfinite(r) || (near && std::isnan(r))) << r;
    ASSERT_TRUE(same_bits(f.peak_ratio, two.correlation.field.peak_ratio));
    ASSERT_TRUE(same_bits(one.volume_a.data, two.volume_a.data));
    ASSERT_TRUE(same_bits(one.volume_b.data, two.volume_b.data));
    const VectorField& g = two.correlation.field;
    ASSERT_TRUE(same_bits(f.dx_mm, g.dx_mm) && same_bits(f.dy_mm, g.dy_mm) && same_bits(f.dz_mm, g.dz_mm));
    ASSERT_TRUE(same_bits(f.valid, g.valid));
    ASSERT_TRUE(same_bits(f.sigma_dx_mm, g.sigma_dx_mm) && same_bits(f.sigma_dy_mm, g.sigma_dy_mm) &&
                same_bits(f.sigma_dz_mm, g.sigma_dz_mm));
    // A valid vector's sigma: non-negative and finite, or NaN on an axis where its peak has no
    // curvature (uncertainty.hpp).
    for (std::size_t n = 0; n < f.valid.size(); ++n) {
      if (!f.valid[n]) continue;
      for (const std::vector<float>* sigma : {&f.sigma_dx_mm, &f.sigma_dy_mm, &f.sigma_dz_mm}) {
        const float s = (*sigma)[n];
        ASSERT_TRUE(std::isnan(s) || (std::isfinite(s) && s >= 0.f)) << "vector " << n << ": sigma " << s;
      }
    }
    ASSERT_TRUE(same_bits(one.correlation.flags, two.correlation.flags));
    for (auto v : f.valid)
      if (v) {
        ++with_valid;
        break;
      }
  }
  // The generator must produce real flows too, not only empty or hopeless frames: at least one
  // case in 20 with a valid vector (tiny 12-voxel boxes with 8-voxel windows validate little; the
  // point here is finiteness and determinism, accuracy is tested elsewhere).
  EXPECT_GT(with_valid, cases / 20) << "measured 26 of the first 300 cases";
}

TEST(PLENOPIV_STRESS_SUITE, NaNAndNegativeImagesAreRefused) {
  const int cases = std::max(10, PLENOPIV_STRESS_CASES / 30);
  for (int i = 0; i < cases; ++i) {
    Case c = make_case(std::uint64_t(100000 + i));
    std::mt19937_64 rng{std::uint64_t(i)};
    const std::size_t at = std::uniform_int_distribution<std::size_t>(0, c.a.size() - 1)(rng);
    const float bad[] = {std::numeric_limits<float>::quiet_NaN(), -1.f, -std::numeric_limits<float>::infinity(),
                         std::numeric_limits<float>::infinity()};
    ImageF& spoiled = (i % 2) ? c.b : c.a;
    spoiled.pixels[at] = bad[i % 4];
    const char* name = (i % 2) ? "frame B" : "frame A";
    try {
      process_pair(fixture().op(c.settings.reconstruction_grid(), c.depth), c.a, c.b, c.settings);
      ADD_FAILURE() << "accepted a frame with " << bad[i % 4];
    } catch (const InputError& e) {
      EXPECT_NE(std::string(e.what()).find(name), std::string::npos) << e.what();
    }
  }
}

TEST(PLENOPIV_STRESS_SUITE, InvalidSettingsAreRefused) {
  Case c = make_case(7);
  for (double mu : {0.0, -0.5, 1.5, std::numeric_limits<double>::quiet_NaN()}) {
    ProcessSettings s = c.settings;
    s.mart.mu = mu;
    EXPECT_THROW(process_pair(fixture().op(s.reconstruction_grid(), c.depth), c.a, c.b, s), InputError) << "mu " << mu;
  }
  ProcessSettings s = c.settings;
  s.mart.iterations = 0;
  EXPECT_THROW(process_pair(fixture().op(s.reconstruction_grid(), c.depth), c.a, c.b, s), InputError);
  s = c.settings;
  s.correlation.passes = {{{64, 64, 64}, 50}};  // larger than the 12-voxel box
  EXPECT_THROW(process_pair(fixture().op(s.reconstruction_grid(), c.depth), c.a, c.b, s), InputError);
  for (int margin : {-1, 7}) {  // the second pass's window is 6 voxels deep
    s = c.settings;
    s.correlation.passes[1].depth_margin = margin;
    EXPECT_THROW(process_pair(fixture().op(s.reconstruction_grid(), c.depth), c.a, c.b, s), InputError) << margin;
  }
  for (int passes : {-1, 5}) {
    s = c.settings;
    s.correlation.final_smoothing = passes;
    EXPECT_THROW(process_pair(fixture().op(s.reconstruction_grid(), c.depth), c.a, c.b, s), InputError) << passes;
  }
  for (int passes : {-1, 9}) {
    s = c.settings;
    s.correlation.depth_prefilter = passes;
    EXPECT_THROW(process_pair(fixture().op(s.reconstruction_grid(), c.depth), c.a, c.b, s), InputError) << passes;
  }
  s = c.settings;
  s.correlation.prefilter = false;
  s.correlation.depth_prefilter = 1;
  EXPECT_THROW(process_pair(fixture().op(s.reconstruction_grid(), c.depth), c.a, c.b, s), InputError);
  s = c.settings;
  ImageF small(20, 20, 1.f);
  EXPECT_THROW(process_pair(fixture().op(s.reconstruction_grid(), c.depth), small, c.b, s), InputError);
}

}  // namespace
}  // namespace plenopiv::process
