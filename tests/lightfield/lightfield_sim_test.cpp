// The light field end to end on the simulator's images: calibrate from its calibration and white
// images (or from the white alone, also with an array whose pitch the camera file has 0.9 %
// wrong), then refocus a simulated particle (sharpest at its true depth) and shift perspective
// (the particle moves as eq 2 predicts).
#include <gtest/gtest.h>

#include <cmath>
#include <iostream>
#include <numbers>

#include "core/calib/calibration.hpp"
#include "core/lightfield/light_field.hpp"
#include "core/lightfield/refocus.hpp"
#include "core/optics/camera_file.hpp"
#include "core/sim/render.hpp"
#include "tests/lightfield/view_shift.hpp"

namespace plenopiv::lightfield {
namespace {

ImageF to_float(const ImageU16& in) {
  ImageF out(in.width, in.height);
  for (std::size_t k = 0; k < in.size(); ++k) out.pixels[k] = in.pixels[k];
  return out;
}

// How the rig is calibrated: from the stopped-down and white images, from the white alone, or from
// the white alone of an array whose lenses are 0.9 % further apart than the camera file says.
enum class Source { spots, white, white_pitch_off };

// The small camera, its true (rotated, offset, jittered) array, and what calibration made of it.
struct Rig {
  optics::CameraModel camera =
      optics::load_camera_file(std::string(PLENOPIV_SOURCE_DIR) + "/systemd/config/camera-small.yaml");
  optics::MicrolensArray truth;
  optics::MicrolensArray lenses;
  ImageF white;

  explicit Rig(Source source) {
    optics::Lattice l = optics::Lattice::nominal(camera);
    l.rotation_rad = 0.5 * std::numbers::pi / 180;
    l.offset_x_mm = 0.011;
    l.offset_y_mm = -0.007;
    if (source == Source::white_pitch_off) {
      l.pitch_x_mm *= 1.009;
      l.pitch_y_mm *= 1.009;
    }
    truth = sim::jittered_array(l, 0.001, 5);
    sim::SensorModel sensor;
    sensor.electrons_per_ray = 20;
    sensor.shot_noise = true;
    sensor.read_noise_electrons = 10;
    sensor.dark_offset_dn = 100;
    if (source == Source::spots) {
      sim::TargetOptions cal_target = sim::calibration_target();
      cal_target.sensor = sensor;
      calib::Calibration cal =
          calib::calibrate(camera, to_float(sim::render_target(camera, truth, cal_target, 11).image));
      sim::TargetOptions white_target = sim::white_target();
      white_target.sensor = sensor;
      white_target.sensor.electrons_per_ray = 5;
      white = calib::make_white_correction(cal, to_float(sim::render_target(camera, truth, white_target, 12).image),
                                           cal.image_stats.background);
      lenses = cal.microlens_array();
      return;
    }
    // White only: 100 rays per pixel, and a dark frame of the same sensor.
    sim::TargetOptions white_target = sim::white_target();
    white_target.rays_per_lens = 30000;
    white_target.sensor = sensor;
    calib::CalibrationFrames frames;
    frames.white = to_float(sim::render_target(camera, truth, white_target, 12).image);
    frames.dark = to_float(sim::apply_sensor(ImageF(850, 850, 0.0f), sensor, 13));
    const calib::Calibration cal = calib::calibrate_camera(camera, frames);
    std::cout << "white-only calibration:\n" << calib::describe(cal);
    if (source == Source::white_pitch_off) {
      EXPECT_NEAR(cal.pitch_ratio, 1.009, 3e-4);
    }
    white = cal.white_correction;
    lenses = cal.microlens_array();
  }
};

const Rig& rig(Source source = Source::spots) {
  static const Rig spots(Source::spots);
  if (source == Source::spots) return spots;
  static const Rig white(Source::white);
  if (source == Source::white) return white;
  static const Rig pitch_off(Source::white_pitch_off);
  return pitch_off;
}

LightField particle_field(const sim::Point3& p, Source source = Source::spots) {
  sim::RenderOptions options;
  options.rays_per_particle = 200000;
  const std::vector<sim::Point3> particles{p};
  const Rig& r = rig(source);
  const auto image = sim::render(r.camera, r.truth, particles, options, 3);
  return rectify(r.camera, r.lenses, to_float(image.image), &r.white);
}

class SimRefocus : public ::testing::TestWithParam<double> {};

TEST_P(SimRefocus, SharpestImageAtTheParticlesTrueDepth) {
  const double z0 = GetParam();
  const LightField field = particle_field({0.31, -0.23, z0});
  // In 0.25 mm steps the maximum landed within 0.5 mm of every depth here (-8 for -8.5, -2.75 for
  // -3, 0, 4.5 for 4.25, 9.25 for 9); 0.5 mm steps keep the test quick.
  const double best_z = sharpest_depth_mm(field, rig().camera, -10, 10, 0.5);
  std::cout << "simulated particle at z = " << z0 << " mm: sharpest refocus at " << best_z << " mm\n";
  EXPECT_NEAR(best_z, z0, 1.0);
}

INSTANTIATE_TEST_SUITE_P(Depths, SimRefocus, ::testing::Values(-8.5, -3.0, 0.0, 4.25, 9.0));

class SimPerspective : public ::testing::TestWithParam<double> {};

// Eq 2: seen from aperture point u, a particle whose image forms at alpha lies at
// x = u (1 - 1/alpha) + x'/alpha on the microlens plane.
TEST_P(SimPerspective, ShiftMatchesEquationTwo) {
  const double z0 = GetParam();
  const LightField field = particle_field({0.12, 0.08, z0});
  const double expected = 1 - 1 / alpha_for_depth(rig().camera, z0);
  // Views within 8 mm of the axis (the aperture radius is 12.5 mm): the outer views sample the rim
  // of each microlens image, where diffraction spills light into the neighbour's image; with
  // |u| <= 10 mm the fitted shift came out 2-4 % low.
  const auto [slope_x, slope_y] = testing_support::view_shift_slopes(field, field.lenses.lattice, 8);
  std::cout << "simulated particle at z = " << z0 << " mm: view shift " << slope_x << ", " << slope_y
            << " mm per mm of aperture; eq 2: " << expected << "\n";
  EXPECT_EQ(slope_x > 0, expected > 0);
  // The view shift is eq 2's.
  EXPECT_NEAR(slope_x, expected, 0.025 * std::abs(expected)) << "measured within 1.5 %";
  EXPECT_NEAR(slope_y, expected, 0.025 * std::abs(expected)) << "measured within 1.5 %";
}

INSTANTIATE_TEST_SUITE_P(Depths, SimPerspective, ::testing::Values(-8.0, 6.0));

// The same from a white-only calibration, and from one whose array's pitch the camera file has
// wrong by 0.9 % (applied as the lens pitch, so refocusing reads every spot where it is).
class WhiteOnlyRefocus : public ::testing::TestWithParam<std::tuple<Source, double>> {};

TEST_P(WhiteOnlyRefocus, SharpestImageAtTheParticlesTrueDepthAndViewsShiftAsEquationTwo) {
  const auto [source, z0] = GetParam();
  const LightField field = particle_field({0.31, -0.23, z0}, source);
  const double best_z = sharpest_depth_mm(field, rig(source).camera, -10, 10, 0.5);
  const double expected = 1 - 1 / alpha_for_depth(rig(source).camera, z0);
  const auto [slope_x, slope_y] = testing_support::view_shift_slopes(field, field.lenses.lattice, 8);
  std::cout << "measured: " << (source == Source::white ? "white-only" : "white-only, pitch 0.9 % off")
            << ": particle at z = " << z0 << " mm: sharpest refocus at " << best_z << " mm; view shift " << slope_x
            << ", " << slope_y << " (eq 2: " << expected << ")\n";
  EXPECT_NEAR(best_z, z0, 1.0) << "measured: exactly at -8 and 6 mm in 0.5 mm steps";
  EXPECT_NEAR(slope_x, expected, 0.025 * std::abs(expected)) << "measured: within 0.8 % of eq 2";
  EXPECT_NEAR(slope_y, expected, 0.025 * std::abs(expected)) << "measured: within 0.8 % of eq 2";
}

INSTANTIATE_TEST_SUITE_P(Calibrations, WhiteOnlyRefocus,
                         ::testing::Values(std::make_tuple(Source::white, -8.0), std::make_tuple(Source::white, 6.0),
                                           std::make_tuple(Source::white_pitch_off, -8.0),
                                           std::make_tuple(Source::white_pitch_off, 6.0)));

}  // namespace
}  // namespace plenopiv::lightfield
