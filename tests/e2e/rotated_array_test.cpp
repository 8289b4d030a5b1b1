// Rotated and irregular microlens arrays: the resampling onto an axis-aligned lattice
// (lightfield::LatticeResampler) and the reconstruction core/process builds on it, against the
// simulator's truth and the same scene through an unrotated camera.
#include <gtest/gtest.h>

#include <tbb/global_control.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <iostream>
#include <numbers>
#include <random>
#include <vector>

#include "core/base/errors.hpp"
#include "core/base/yaml_access.hpp"
#include "core/calib/calibration.hpp"
#include "core/calib/nominal_calibration.hpp"
#include "core/lightfield/lattice_resampling.hpp"
#include "core/process/process.hpp"
#include "core/recon/mart.hpp"
#include "core/recon/quality.hpp"
#include "core/recon/weights.hpp"
#include "core/sim/exact_volume.hpp"
#include "core/sim/render.hpp"
#include "tests/support/cameras.hpp"
#include "tests/support/mean_displacement.hpp"

namespace plenopiv {
namespace {

using testing_support::small_camera;

const optics::CameraModel& camera() {
  static const optics::CameraModel cam = small_camera();
  return cam;
}

// The simulator's true array: the nominal lattice rotated by `degrees`, offset, each lens moved
// by Gaussian jitter of `jitter_mm` (1 um = 0.14 px, as calibration_sim_test's array).
optics::MicrolensArray true_array(double degrees, double jitter_mm) {
  optics::Lattice l = optics::Lattice::nominal(camera());
  l.rotation_rad = degrees * std::numbers::pi / 180;
  l.offset_x_mm = 0.011;
  l.offset_y_mm = -0.007;
  return sim::jittered_array(l, jitter_mm, 5);
}

ImageF render(const optics::MicrolensArray& array, const std::vector<sim::Point3>& particles, std::uint64_t seed) {
  sim::RenderOptions o;
  o.rays_per_particle = 20000;
  return sim::render(camera(), array, particles, o, seed).rays;
}

// 36 particles over most of the field of view (the corners of a rotated array depart most from
// the axis-aligned lattice) and 4 mm of depth, far enough apart for one fit window each.
std::vector<sim::Point3> scene() {
  std::vector<sim::Point3> p;
  int k = 0;
  for (int j = 0; j < 6; ++j)
    for (int i = 0; i < 6; ++i) p.push_back({-2.07 + 0.83 * i, -2.04 + 0.81 * j, -2.0 + 4.0 * ((k++ * 7) % 36) / 35.0});
  return p;
}

Grid3 scene_grid() {
  Grid3 g;
  g.shape = {40, 40, 40};
  g.spacing_mm = {0.125, 0.125, 0.125};
  g.origin_mm = {-2.4375, -2.4375, -2.4375};
  return g;
}

double ncc(const ImageF& a, const ImageF& b) {
  double ma = 0, mb = 0;
  for (std::size_t i = 0; i < a.size(); ++i) {
    ma += a.pixels[i];
    mb += b.pixels[i];
  }
  ma /= double(a.size());
  mb /= double(a.size());
  double ab = 0, aa = 0, bb = 0;
  for (std::size_t i = 0; i < a.size(); ++i) {
    const double x = a.pixels[i] - ma, y = b.pixels[i] - mb;
    ab += x * y;
    aa += x * x;
    bb += y * y;
  }
  return ab / std::sqrt(aa * bb);
}

TEST(LatticeResampling, AnAxisAlignedLatticeIsResampledOntoItselfExactly) {
  const auto lenses = optics::MicrolensArray::from_lattice(optics::Lattice::nominal(camera()));
  const ImageF white = calib::geometric_white_image(camera(), lenses);
  const lightfield::LatticeResampler r(camera(), lenses, white);
  EXPECT_EQ(r.coverage().full, 2500);
  EXPECT_EQ(r.lenses().centres_mm, lenses.centres_mm);
  const ImageF image = render(lenses, scene(), 3);
  EXPECT_EQ(r.resample(image).pixels, image.pixels);
  EXPECT_EQ(r.white().pixels, white.pixels);
}

TEST(LatticeResampling, FollowsTheMeasuredCentresNotJustTheFittedLattice) {
  // Every measured centre one pitch right of its lattice position: the lens at lattice position i
  // is lens i - 1. Read by the fitted lattice alone, virtual lens i would take lens i and sample
  // 17 px off; followed through the measured centres it takes lens i - 1, whose spot is where the
  // virtual one is, and the resampling is the identity there (lens column 0 has no lens left of it).
  const optics::Lattice l = optics::Lattice::nominal(camera());
  optics::MicrolensArray shifted = optics::MicrolensArray::from_lattice(l);
  for (auto& c : shifted.centres_mm) c[0] += l.pitch_x_mm;
  const lightfield::LatticeResampler r(camera(), shifted, ImageF(850, 850, 1.f));
  EXPECT_EQ(r.coverage().none, 50);  // virtual lens column 0
  std::mt19937 rng(1);
  std::uniform_real_distribution<float> value(0.f, 100.f);
  ImageF raw(850, 850);
  for (float& v : raw.pixels) v = value(rng);
  const ImageF out = r.resample(raw);
  const double s_i = camera().image_distance_mm(), f_l = camera().microlens().focal_length_mm;
  const double spot0 =
      optics::sensor_mm_to_column(camera().sensor(), optics::lens_centre_to_spot_mm(l.position(0, 0)[0], s_i, f_l));
  const double spot_pitch = optics::lens_centre_to_spot_mm(l.pitch_x_mm, s_i, f_l) / camera().sensor().pixel_pitch_mm;
  std::size_t compared = 0, equal = 0;
  for (int row = 0; row < 850; ++row)
    for (int col = int(std::ceil(spot0 + 0.5 * spot_pitch)); col < 850; ++col) {
      ++compared;
      equal += out.at(col, row) == raw.at(col, row);
    }
  EXPECT_EQ(equal, compared);
  EXPECT_GT(compared, 800u * 800u);
}

TEST(LatticeResampling, ARotatedArraysImageLooksLikeTheAxisAlignedOnes) {
  // The same particles through the rotated, jittered array, resampled, against the image the
  // virtual (axis-aligned) lattice itself records; and the resampled white correction against the
  // virtual lattice's geometric one.
  for (double degrees : {0.3, 1.0}) {
    const auto array = true_array(degrees, 0.001);
    const lightfield::LatticeResampler r(camera(), array, calib::geometric_white_image(camera(), array));
    EXPECT_EQ(r.lenses().lattice.rotation_rad, 0.0);
    EXPECT_NEAR(r.lenses().lattice.offset_x_mm, 0.011, 1e-12);
    const ImageF resampled = r.resample(render(array, scene(), 3));
    const ImageF direct = render(r.lenses(), scene(), 3);
    const double image_ncc = ncc(resampled, direct);
    const double white_ncc = ncc(r.white(), calib::geometric_white_image(camera(), r.lenses()));
    std::cout << "measured: " << degrees << " deg: image NCC " << image_ncc << ", white NCC " << white_ncc
              << ", virtual lenses full/partial/none " << r.coverage().full << "/" << r.coverage().partial << "/"
              << r.coverage().none << "\n";
    // The resampled image resembles the one the virtual lattice would record, less so as the
    // rotation grows: the array samples the light field once per lens, and where a virtual lens
    // falls between calibrated ones (a third of a pitch off at 1 deg in the corners) the in-focus
    // particles' light, on one or two lenses, is blended over neighbours. The resampled white
    // matches the virtual lattice's geometric white (nearest raw pixels).
    EXPECT_GT(image_ncc, degrees < 0.5 ? 0.92 : 0.78) << "measured 0.948 (0.3 deg), 0.821 (1 deg)";
    EXPECT_GT(white_ncc, 0.95) << "measured 0.969 (0.3 deg), 0.967 (1 deg)";
    EXPECT_EQ(r.coverage().full + r.coverage().partial + r.coverage().none, 2500);
  }
  // A different sensor size is named.
  const auto array = true_array(0.3, 0.001);
  const lightfield::LatticeResampler r(camera(), array, calib::geometric_white_image(camera(), array));
  EXPECT_THROW(r.resample(ImageF(10, 10)), InputError);
  EXPECT_THROW(lightfield::LatticeResampler(camera(), array, ImageF(10, 10)), InputError);
}

// A virtual lens within the tolerance of its nearest calibrated lens takes that lens alone: the
// pixels that recorded nothing stay 0. A blend of every lens lights most of them; a rotated array's
// lenses far from the centre are still blended.
TEST(LatticeResampling, ALensWithinTheToleranceIsTakenAloneAndDarkPixelsStayDark) {
  const auto lit = [](const ImageF& image) {
    return std::size_t(std::count_if(image.pixels.begin(), image.pixels.end(), [](float p) { return p > 0.f; }));
  };
  const auto jittered = true_array(0.0, 0.001);  // 0.14 px RMS: every lens within 1 px
  const ImageF white = calib::geometric_white_image(camera(), jittered);
  const ImageF image = render(jittered, scene(), 3);
  const lightfield::LatticeResampler blended(camera(), jittered, white, 0.0), nearest(camera(), jittered, white, 1.0);
  EXPECT_EQ(nearest.coverage().nearest, nearest.coverage().full + nearest.coverage().partial);
  EXPECT_LT(blended.coverage().nearest, nearest.coverage().nearest / 10);
  const std::size_t raw = lit(image), with_blend = lit(blended.resample(image)), alone = lit(nearest.resample(image));
  std::cout << "measured: lit pixels raw " << raw << ", blended " << with_blend << ", nearest lens " << alone << "\n";
  EXPECT_LE(alone, raw + raw / 100) << "the same pixels, up to lenses whose spot shifts by a pixel";
  EXPECT_GT(with_blend, 2 * raw) << "a blend lights pixels that recorded nothing";

  const auto rotated = true_array(1.0, 0.001);
  const lightfield::LatticeResampler r(camera(), rotated, calib::geometric_white_image(camera(), rotated), 1.0);
  std::cout << "measured: 1 deg: " << r.coverage().nearest << " of " << r.coverage().full + r.coverage().partial
            << " virtual lenses from their nearest lens alone\n";
  EXPECT_GT(r.coverage().nearest, 0);
  EXPECT_LT(r.coverage().nearest, r.coverage().full / 5);
  for (const double bad : {-1.0, std::nan("")})
    EXPECT_THROW(lightfield::LatticeResampler(camera(), rotated, white, bad), InputError) << bad;
}

TEST(LatticeResampling, SameImageAtOneAndTwoThreads) {
  const auto array = true_array(1.0, 0.001);
  const ImageF image = render(array, scene(), 3);
  auto run = [&](int threads) {
    tbb::global_control limit(tbb::global_control::max_allowed_parallelism, threads);
    const lightfield::LatticeResampler r(camera(), array, calib::geometric_white_image(camera(), array));
    return r.resample(image).pixels;
  };
  EXPECT_EQ(run(1), run(2));
}

struct SceneErrors {
  double lateral_rms_voxel = 0, depth_rms_voxel = 0, q = 0;
  std::string note;
};

// Reconstructs scene() through `array` as core/process does (PairOperator chooses raw pixels or the
// resampled lattice), then fits every particle and compares with the exact volume.
SceneErrors reconstruct_scene(const optics::MicrolensArray& array) {
  const Grid3 g = scene_grid();
  const process::PairOperator op(camera(), array, calib::geometric_white_image(camera(), array), g);
  ImageF scratch;
  recon::MartSettings s;
  s.iterations = 20;
  s.mu = 1.0;
  // Half a ray: the simulator's images are noise-free, and resampling spreads each raw pixel over
  // its neighbours, so without a threshold the pixels that recorded nothing would no longer be
  // dark and MART would keep the voxels they rule out (Q* about halves for the jitter-only array;
  // the unrotated raw image gives the same Q* at 0 and 0.5).
  s.noise_threshold = 0.5f;
  const std::vector<sim::Point3> particles = scene();
  const Volume v = recon::reconstruct(op.weights(), op.prepare(render(array, particles, 3), scratch), s).volume;
  SceneErrors e;
  e.note = op.note();
  for (const auto& p : particles) {
    const auto fit = recon::fit_particle(v, p, {3, 3, 10});
    EXPECT_TRUE(fit);
    if (!fit) continue;
    const double ex = (fit->position_mm[0] - p[0]) / 0.125, ey = (fit->position_mm[1] - p[1]) / 0.125;
    const double ez = (fit->position_mm[2] - p[2]) / 0.125;
    e.lateral_rms_voxel += ex * ex + ey * ey;
    e.depth_rms_voxel += ez * ez;
  }
  e.lateral_rms_voxel = std::sqrt(e.lateral_rms_voxel / double(particles.size()));
  e.depth_rms_voxel = std::sqrt(e.depth_rms_voxel / double(particles.size()));
  e.q = recon::quality_factor(v, sim::render_exact_volume(g, particles));
  return e;
}

TEST(RotatedArray, ReconstructsAsWellAsTheUnrotatedCamera) {
  const auto t0 = std::chrono::steady_clock::now();
  const SceneErrors ref = reconstruct_scene(optics::MicrolensArray::from_lattice(optics::Lattice::nominal(camera())));
  EXPECT_TRUE(ref.note.empty()) << ref.note;  // the nominal lattice: raw pixels
  std::cout << "measured: unrotated (raw pixels): lateral " << ref.lateral_rms_voxel << " voxel rms, depth "
            << ref.depth_rms_voxel << ", Q* " << ref.q << "\n";
  for (double degrees : {0.0, 0.3, 1.0, 2.0}) {
    const SceneErrors e = reconstruct_scene(true_array(degrees, 0.001));
    std::cout << "measured: " << degrees << " deg + 1 um jitter: lateral " << e.lateral_rms_voxel
              << " voxel rms, depth " << e.depth_rms_voxel << ", Q* " << e.q << "\n  " << e.note << "\n";
    // The jitter alone departs under recon::kSeparableTolerancePx (raw pixels, the separable
    // weights on the lens columns' and rows' means); a rotation of 0.3 deg or more, beyond it.
    if (degrees == 0.0)
      EXPECT_TRUE(e.note.empty()) << e.note;
    else
      EXPECT_NE(e.note.find("image resampled onto an axis-aligned lattice"), std::string::npos) << e.note;
    // Against the unrotated camera: lateral error at most 0.1 voxel larger, depth error at most 0.7
    // (single fits scatter by a few voxels in depth), Q* not lower (the blend across lenses
    // smooths the volume, which Q* rewards).
    EXPECT_LT(e.lateral_rms_voxel, ref.lateral_rms_voxel + 0.1)
        << degrees << " deg (measured +0.04 at most, at 2 deg, against 0.425)";
    EXPECT_LT(e.depth_rms_voxel, ref.depth_rms_voxel + 0.7) << degrees << " deg (measured -0.10 to +0.44 against 1.86)";
    EXPECT_GT(e.q, ref.q - 0.05) << degrees << " deg (measured 0.390-0.515 against 0.369)";
  }
  std::cout << "measured: test time " << std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count()
            << " s\n";
}

}  // namespace
}  // namespace plenopiv

namespace plenopiv {
namespace {

// The whole path a real camera takes: the rotated array calibrated from the simulator's
// calibration image (core/calib), then process_pair with process.yaml's settings on a pair with a
// known uniform displacement (process_cli_test's scene), against the same particles through the
// unrotated camera. The white correction is the geometric one of the calibrated lenses, so that
// this test is about the resampling alone (the measured white: tests/e2e/measured_white_test.cpp).
TEST(RotatedArray, ProcessPairWithARotatedCalibration) {
  const auto t0 = std::chrono::steady_clock::now();
  const process::ProcessSettings s = process::process_settings_from(YamlMap(load_yaml_text(R"(
dt_s: 0.0001
volume: {x_mm: [-2, 2], y_mm: [-2, 2], z_mm: [0, 4], voxel_mm: 0.125, depth_guard_mm: 1}
reconstruction: {iterations: 20, mu: 1, start: mlos, noise_threshold: 0.5, dark_weight_cutoff: 0.9}
correlation:
  passes: [{window: 32, overlap_percent: 50}, {window: 24, overlap_percent: 75}, {window: 16, overlap_percent: 75}]
  median: {threshold: 2, epsilon_voxel: 0.1, radius: 2}
)",
                                                                                           "rotated.yaml"),
                                                                            "rotated.yaml"));
  const sim::Point3 shift{0.25, 0.125, 0.25};  // 2, 1, 2 voxels
  // 1 particle per microlens over the field of view, in a box 0.5 mm beyond the volume's depth.
  const std::vector<sim::Point3> a = sim::random_particles({{-2.5, -2.5, -0.5}, {2.5, 2.5, 4.5}}, 1600, 21);
  std::vector<sim::Point3> b = a;
  for (auto& p : b)
    for (int k = 0; k < 3; ++k) p[std::size_t(k)] += shift[std::size_t(k)];
  sim::RenderOptions ro;
  ro.rays_per_particle = 2000;

  auto mean_shift = [&](const optics::MicrolensArray& truth, const optics::MicrolensArray& lenses, std::string& note) {
    const process::PairOperator op(camera(), lenses, calib::geometric_white_image(camera(), lenses),
                                   s.reconstruction_grid());
    const process::PairResult r = process::process_pair(op, sim::render(camera(), truth, a, ro, 3).rays,
                                                        sim::render(camera(), truth, b, ro, 4).rays, s);
    note = r.lattice_note;
    const VectorField& f = r.correlation.field;
    const testing_support::MeanDisplacement m = testing_support::mean_displacement(f);
    EXPECT_GT(m.valid, f.grid.count() / 2);
    return m.mm;
  };
  std::string note;
  const auto nominal = optics::MicrolensArray::from_lattice(optics::Lattice::nominal(camera()));
  const auto ref = mean_shift(nominal, nominal, note);
  EXPECT_TRUE(note.empty()) << note;
  std::cout << "measured: unrotated: mean displacement " << ref[0] << " " << ref[1] << " " << ref[2] << " mm (truth "
            << shift[0] << " " << shift[1] << " " << shift[2] << ")\n";
  for (double degrees : {0.05, 0.3, 1.0}) {
    const auto array = true_array(degrees, 0.001);
    sim::TargetOptions target = sim::calibration_target();
    target.rays_per_lens = 4000;
    const calib::Calibration cal = calib::calibrate(camera(), sim::render_target(camera(), array, target, 11).rays);
    const auto rot = mean_shift(array, cal.microlens_array(), note);
    std::cout << "measured: " << degrees << " deg (calibrated "
              << cal.spot_lattice.rotation_rad * 180 / std::numbers::pi << " deg): mean displacement " << rot[0] << " "
              << rot[1] << " " << rot[2] << " mm\n  " << note << "\n";
    // 0.05 deg departs under recon::kSeparableTolerancePx: raw pixels, the separable weights on the
    // calibrated lens columns' and rows' means.
    char expected[96];
    std::snprintf(expected, sizeof expected,
                  "image resampled onto an axis-aligned lattice: calibrated array rotated %.2f deg", degrees);
    if (degrees < 0.1) {
      EXPECT_TRUE(note.empty()) << note;
    } else {
      EXPECT_NE(note.find(expected), std::string::npos) << note;
      EXPECT_NE(note.find("from their nearest lens alone (within 1.00 px)"), std::string::npos) << note;
    }
    // Lateral within 0.01 mm of the unrotated camera's; the depth component recovers less as the
    // rotation grows (the blend across lenses widens each particle's image), at least 60 % of the
    // unrotated camera's at 0.3 deg and 40 % at 1 deg; within the tolerance as much as unrotated.
    for (int k = 0; k < 2; ++k)
      EXPECT_NEAR(rot[std::size_t(k)], ref[std::size_t(k)], 0.01)
          << degrees << " axis " << k << " (measured within 0.002 mm)";
    EXPECT_GT(rot[2], (degrees < 0.1   ? 0.9
                       : degrees < 0.5 ? 0.6
                                       : 0.4) *
                          ref[2])
        << degrees << " deg (measured 0.144 mm at 0.05 deg, 0.119 at 0.3, 0.072 at 1, 0.154 unrotated)";
  }
  std::cout << "measured: test time " << std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count()
            << " s\n";
}

// A resampled frame blends lenses with weights down to float rounding, so its own faintest lit
// pixel says nothing of what a dark pixel recorded: process_pair gives MART the raw frames' floor
// (half a ray for these integer frames) there, and raw pixels keep each frame's own.
TEST(RotatedArray, ResampledFramesKeepTheRawFramesDarkFloor) {
  const process::ProcessSettings s = process::process_settings_from(YamlMap(load_yaml_text(R"(
dt_s: 0.0001
volume: {x_mm: [-1, 1], y_mm: [-1, 1], z_mm: [0, 2], voxel_mm: 0.125, depth_guard_mm: 0.5}
reconstruction: {iterations: 2, mu: 1, noise_threshold: 0}
correlation: {passes: [{window: 16, overlap_percent: 50}]}
)",
                                                                                           "floor.yaml"),
                                                                            "floor.yaml"));
  std::vector<sim::Point3> a = sim::random_particles({{-1.5, -1.5, -0.5}, {1.5, 1.5, 2.5}}, 200, 31), b = a;
  for (auto& p : b) p[0] += 0.25;
  for (const double degrees : {0.0, 0.3}) {
    const auto array = degrees > 0 ? true_array(degrees, 0.001)
                                   : optics::MicrolensArray::from_lattice(optics::Lattice::nominal(camera()));
    const ImageF fa = render(array, a, 5), fb = render(array, b, 6);
    const process::PairOperator op(camera(), array, calib::geometric_white_image(camera(), array),
                                   s.reconstruction_grid());
    const process::PairResult r = process::process_pair(op, fa, fb, s);
    const auto floor_of = [](const ImageF& f) { return recon::dark_floor_of({f.pixels.data(), f.pixels.size()}, 0.f); };
    ASSERT_EQ(floor_of(fa), 0.5f) << "the simulator's frames count whole rays";
    if (!op.resampler()) {
      EXPECT_EQ(degrees, 0.0);
      EXPECT_EQ(op.dark_floor(fa, 0.f), 0.f) << "raw pixels: the image's own";
      EXPECT_EQ(r.skipped_a.dark_floor, floor_of(fa));
      EXPECT_EQ(r.skipped_b.dark_floor, floor_of(fb));
      continue;
    }
    ImageF scratch;
    const float resampled_own = floor_of(op.prepare(fa, scratch));
    std::cout << "measured: " << degrees << " deg: the resampled frame's own floor " << resampled_own
              << ", the raw frames' " << std::min(floor_of(fa), floor_of(fb)) << "\n";
    EXPECT_LT(resampled_own, 0.01f * floor_of(fa)) << "the blend's faintest pixel, far below a ray";
    EXPECT_EQ(op.dark_floor(fa, 0.f), floor_of(fa));
    EXPECT_EQ(op.dark_floor(fa, 2.f), 2.f) << "the noise threshold, where there is one";
    EXPECT_EQ(r.skipped_a.dark_floor, std::min(floor_of(fa), floor_of(fb)));
    EXPECT_EQ(r.skipped_b.dark_floor, std::min(floor_of(fa), floor_of(fb)));
  }
}

// A hex array (rotated 0.3 deg, jittered) through the same resampling onto a rectangular lattice
// one pitch apart (13 % fewer lens rows than the hex array has). No raw-pixel reference exists for
// hex; the rect camera's figures above are the yardstick.
TEST(RotatedArray, AHexArrayIsResampledOntoARectangularLattice) {
  const auto cam = small_camera("hex");
  optics::Lattice l = optics::Lattice::nominal(cam);
  l.rotation_rad = 0.3 * std::numbers::pi / 180;
  const auto array = sim::jittered_array(l, 0.001, 5);
  const Grid3 g = scene_grid();
  const process::PairOperator op(cam, array, calib::geometric_white_image(cam, array), g);
  EXPECT_NE(op.note().find("hexagonal (49 x 50 lenses, rotated 0.30 deg), resampled onto 49 x 43"), std::string::npos)
      << op.note();
  recon::MartSettings s;
  s.iterations = 20;
  s.mu = 1.0;
  s.noise_threshold = 0.5f;
  const auto particles = scene();
  sim::RenderOptions o;
  o.rays_per_particle = 20000;
  ImageF scratch;
  const Volume v =
      recon::reconstruct(op.weights(), op.prepare(sim::render(cam, array, particles, o, 3).rays, scratch), s).volume;
  double lat = 0, dep = 0;
  for (const auto& p : particles) {
    const auto fit = recon::fit_particle(v, p, {3, 3, 10});
    ASSERT_TRUE(fit);
    lat += std::pow((fit->position_mm[0] - p[0]) / 0.125, 2) + std::pow((fit->position_mm[1] - p[1]) / 0.125, 2);
    dep += std::pow((fit->position_mm[2] - p[2]) / 0.125, 2);
  }
  lat = std::sqrt(lat / double(particles.size()));
  dep = std::sqrt(dep / double(particles.size()));
  const double q = recon::quality_factor(v, sim::render_exact_volume(g, particles));
  std::cout << "measured: hex 0.3 deg (resampled): lateral " << lat << " voxel rms, depth " << dep << ", Q* " << q
            << "\n  " << op.note() << "\n";
  // A hex array reconstructs, through the resampling, nearly as well as the unrotated rect camera.
  EXPECT_LT(lat, 0.6) << "measured 0.465 (rect unrotated: 0.425)";
  EXPECT_LT(dep, 3.2) << "measured 2.71 (rect unrotated: 1.86)";
  EXPECT_GT(q, 0.2) << "measured 0.246 (rect unrotated: 0.371)";
}

// What stays refused: the separable operator itself, on raw pixels, for a rotated array.
TEST(RotatedArray, TheSeparableOperatorStillRefusesARotatedArrayByName) {
  const auto array = true_array(0.3, 0.0);
  const recon::SeparableLattice sep = recon::separable_lattice(array);
  EXPECT_FALSE(sep.separable(camera().sensor().pixel_pitch_mm));
  EXPECT_TRUE(recon::separable_lattice(optics::MicrolensArray::from_lattice(optics::Lattice::nominal(camera())))
                  .separable(camera().sensor().pixel_pitch_mm));
  try {
    recon::WeightingOperator(camera(), array, scene_grid(), calib::geometric_white_image(camera(), array));
    ADD_FAILURE() << "a rotated array was accepted";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("rotated or warped array"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace plenopiv
