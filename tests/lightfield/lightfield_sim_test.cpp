// The light field end to end on the simulator's images: calibrate from its calibration and white
// images, then refocus a simulated particle (sharpest at its true depth) and shift perspective
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

// The small camera, its true (rotated, offset, jittered) array, and what calibration made of it.
struct Rig {
  optics::CameraModel camera = optics::load_camera_file(std::string(PLENOPIV_SOURCE_DIR) + "/systemd/config/camera-small.yaml");
  optics::MicrolensArray truth;
  optics::MicrolensArray lenses;
  ImageF white;

  Rig() {
    optics::Lattice l = optics::Lattice::nominal(camera);
    l.rotation_rad = 0.5 * std::numbers::pi / 180;
    l.offset_x_mm = 0.011;
    l.offset_y_mm = -0.007;
    truth = sim::jittered_array(l, 0.001, 5);
    sim::SensorModel sensor;
    sensor.electrons_per_ray = 20;
    sensor.shot_noise = true;
    sensor.read_noise_electrons = 10;
    sensor.dark_offset_dn = 100;
    sim::TargetOptions cal_target = sim::calibration_target();
    cal_target.sensor = sensor;
    calib::Calibration cal = calib::calibrate(camera, to_float(sim::render_target(camera, truth, cal_target, 11).image));
    sim::TargetOptions white_target = sim::white_target();
    white_target.sensor = sensor;
    white_target.sensor.electrons_per_ray = 5;
    white = calib::make_white_correction(cal, to_float(sim::render_target(camera, truth, white_target, 12).image),
                                         cal.image_stats.background);
    lenses = cal.microlens_array();
  }
};

const Rig& rig() {
  static const Rig r;
  return r;
}

LightField particle_field(const sim::Point3& p) {
  sim::RenderOptions options;
  options.rays_per_particle = 200000;
  const std::vector<sim::Point3> particles{p};
  const auto image = sim::render(rig().camera, rig().truth, particles, options, 3);
  return rectify(rig().camera, rig().lenses, to_float(image.image), &rig().white);
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
  // Measured within 1.5 % (0.08632/0.08711 vs 0.08696 at z = -8; -0.05685/-0.05579 vs -0.05660 at 6).
  EXPECT_NEAR(slope_x, expected, 0.025 * std::abs(expected));
  EXPECT_NEAR(slope_y, expected, 0.025 * std::abs(expected));
}

INSTANTIATE_TEST_SUITE_P(Depths, SimPerspective, ::testing::Values(-8.0, 6.0));

}  // namespace
}  // namespace plenopiv::lightfield
