// Light field: eq 1 per pixel, rectification, refocusing to the particle's depth (eqs 2-4) and the
// perspective shift that eq 2 predicts, on ray-traced point particles.
#include <gtest/gtest.h>
#include <tbb/global_control.h>

#include <cmath>
#include <iostream>

#include "core/base/errors.hpp"
#include "core/lightfield/light_field.hpp"
#include "core/lightfield/refocus.hpp"
#include "core/optics/camera_file.hpp"
#include "tests/lightfield/particle_render.hpp"
#include "tests/lightfield/view_shift.hpp"
#include "tests/support/cameras.hpp"

namespace plenopiv::lightfield {
namespace {

using testing_support::PointParticle;
using testing_support::render_particles;

using testing_support::small_camera;

// A slightly rotated, offset array, as calibration finds it.
optics::MicrolensArray measured_array(const optics::CameraModel& cam) {
  optics::Lattice l = optics::Lattice::nominal(cam);
  l.rotation_rad = 0.004;
  l.offset_x_mm = 0.01;
  l.offset_y_mm = -0.006;
  return optics::MicrolensArray::from_lattice(l);
}

TEST(PixelRays, EquationOneWithItsSign) {
  const auto cam = small_camera();
  const auto lenses = measured_array(cam);
  const PixelRays rays = pixel_rays(cam, lenses);
  const auto& s = cam.sensor();
  const double s_i = cam.image_distance_mm(), f_l = cam.microlens().focal_length_mm;
  // Lens (25, 25): its spot, and the pixels right of and below it.
  const auto& c = lenses.centre(25, 25);
  const double col = optics::sensor_mm_to_column(s, optics::lens_centre_to_spot_mm(c[0], s_i, f_l));
  const double row = optics::sensor_mm_to_row(s, optics::lens_centre_to_spot_mm(c[1], s_i, f_l));
  const int x = int(std::lround(col)), y = int(std::lround(row));
  const std::size_t k = std::size_t(y) * s.width_px + x;
  EXPECT_EQ(rays.lens[k], 25 * 50 + 25);
  EXPECT_FLOAT_EQ(rays.x_mm[k], float(c[0]));
  const double du = s.pixel_pitch_mm * s_i / f_l;  // one pixel of the lens image in the aperture: 1.48 mm
  EXPECT_NEAR(rays.u_mm[k], (col - x) * du, 1e-4);
  EXPECT_NEAR(rays.u_mm[k + 1] - rays.u_mm[k], -du, 1e-4);  // right of the spot: left of the aperture
  EXPECT_NEAR(rays.v_mm[k + s.width_px] - rays.v_mm[k], -du, 1e-4);
  EXPECT_EQ(rays.lens[0], -1);  // the corner pixel lies beyond the array
}

TEST(Rectify, SubApertureSamplesAreTheRawPixelsTheyMapTo) {
  const auto cam = small_camera();
  const auto lenses = optics::MicrolensArray::from_lattice(optics::Lattice::nominal(cam));
  ImageF raw(850, 850);
  for (int y = 0; y < 850; ++y)
    for (int x = 0; x < 850; ++x) raw.at(x, y) = float(3 * x + 7 * y);  // bilinear is exact on a plane
  const LightField f = rectify(cam, lenses, raw, nullptr);
  EXPECT_EQ(f.sampling.n_u, 17);  // 16.89 px per lens image
  const double s_i = cam.image_distance_mm(), f_l = cam.microlens().focal_length_mm;
  const auto& c = lenses.centre(10, 30);
  const int iu = 5, iv = 11;
  const double col = optics::sensor_mm_to_column(
      cam.sensor(), optics::lens_centre_to_spot_mm(c[0], s_i, f_l) - f.sampling.u(iu) * f_l / s_i);
  const double row = optics::sensor_mm_to_row(
      cam.sensor(), optics::lens_centre_to_spot_mm(c[1], s_i, f_l) - f.sampling.v(iv) * f_l / s_i);
  ASSERT_TRUE(f.valid[f.index(10, 30, iu, iv)]);
  EXPECT_NEAR(f.at(10, 30, iu, iv), 3 * col + 7 * row, 2e-3);
  EXPECT_FALSE(f.valid[f.index(10, 30, 0, 0)]);  // the corner of the (u, v) square is off the aperture
  EXPECT_THROW(rectify(cam, lenses, ImageF(849, 850), nullptr), InputError);
}

class RefocusDepth : public ::testing::TestWithParam<double> {};

TEST_P(RefocusDepth, SharpestImageAtTheParticleDepth) {
  const double z0 = GetParam();
  const auto cam = small_camera();
  const auto lenses = measured_array(cam);
  const PointParticle p{0.37, -0.21, z0, 1000};
  const ImageF raw = render_particles(cam, lenses, {p}, 300);
  const LightField field = rectify(cam, lenses, raw, nullptr);
  // Swept in 0.25 mm steps the maximum landed within 0.25 mm of every depth below (-7.75 for -8,
  // 9.25 for 9, the others exact); the test sweeps in 0.5 mm steps to stay fast.
  const double best_z = sharpest_depth_mm(field, cam, -10, 10, 0.5);
  std::cout << "particle at z = " << z0 << " mm: sharpest refocus at " << best_z << " mm\n";
  EXPECT_NEAR(best_z, z0, 1.0);
}

INSTANTIATE_TEST_SUITE_P(Depths, RefocusDepth, ::testing::Values(-8.0, -3.5, 0.0, 2.75, 9.0));

TEST(Refocus, HexArraySharpestAtTheParticleDepth) {
  const auto cam = small_camera("hex");
  const auto lenses = measured_array(cam);
  const PointParticle p{-0.2, 0.3, 5.0, 1000};
  const LightField field = rectify(cam, lenses, render_particles(cam, lenses, {p}, 300), nullptr);
  const double best_z = sharpest_depth_mm(field, cam, -10, 10, 0.5);
  std::cout << "hex: particle at z = 5 mm: sharpest refocus at " << best_z << " mm\n";
  EXPECT_NEAR(best_z, 5.0, 1.0);
}

class PerspectiveShift : public ::testing::TestWithParam<double> {};

// Eq 2: in the view from u, a particle whose image forms at x' (alpha) lies at
// x = u (1 - 1/alpha) + x'/alpha on the microlens plane: it moves by (1 - 1/alpha) per mm of u,
// with u for a particle beyond the focal plane (alpha < 1) and against u for a nearer one.
TEST_P(PerspectiveShift, MovesAsEquationTwoPredicts) {
  const double z0 = GetParam();
  const auto cam = small_camera();
  const auto lenses = measured_array(cam);
  const PointParticle p{0.15, 0.1, z0, 1000};
  const LightField field = rectify(cam, lenses, render_particles(cam, lenses, {p}, 300), nullptr);
  const auto ip = testing_support::image_point(cam, p);
  const double expected_slope = 1 - 1 / ip.alpha;
  // Least-squares slope of the view centroid against u (v = 0) and against v (u = 0).
  const auto [slope_x, slope_y] = testing_support::view_shift_slopes(field, lenses.lattice, 10);
  std::cout << "z = " << z0 << " mm: view shift " << slope_x << ", " << slope_y << " mm per mm of u, v; eq 2 "
            << expected_slope << "\n";
  EXPECT_EQ(slope_x > 0, expected_slope > 0);
  // The view shift is eq 2's.
  EXPECT_NEAR(slope_x, expected_slope, 0.02 * std::abs(expected_slope)) << "measured within 0.2 %";
  EXPECT_NEAR(slope_y, expected_slope, 0.02 * std::abs(expected_slope)) << "measured within 0.2 %";
  EXPECT_THROW(perspective_view(field, 20, 0), InputError);
}

INSTANTIATE_TEST_SUITE_P(Depths, PerspectiveShift, ::testing::Values(-8.0, 6.0));

TEST(Refocus, SameImageAtOneAndTwoThreads) {
  const auto cam = small_camera();
  const auto lenses = measured_array(cam);
  const LightField field = rectify(cam, lenses, render_particles(cam, lenses, {{0.1, 0.2, 3.0, 1000}}, 100), nullptr);
  ImageF one, two;
  {
    tbb::global_control c(tbb::global_control::max_allowed_parallelism, 1);
    one = refocus(field, alpha_for_depth(cam, 3.0));
  }
  {
    tbb::global_control c(tbb::global_control::max_allowed_parallelism, 2);
    two = refocus(field, alpha_for_depth(cam, 3.0));
  }
  EXPECT_EQ(one.pixels, two.pixels);
  EXPECT_THROW(alpha_for_depth(cam, -60), InputError);
}

// depth_for_alpha undoes alpha_for_depth across the volume and says NaN where no object plane is.
TEST(Refocus, DepthForAlphaIsTheInverseOfAlphaForDepth) {
  const auto cam = small_camera();
  for (const double z : {-20.0, -3.5, 0.0, 2.25, 40.0}) {
    EXPECT_NEAR(depth_for_alpha(cam, alpha_for_depth(cam, z)), z, 1e-9 * (1 + std::abs(z))) << z;
  }
  EXPECT_TRUE(std::isnan(depth_for_alpha(cam, cam.main_lens().focal_length_mm / cam.image_distance_mm())));
}

}  // namespace
}  // namespace plenopiv::lightfield

namespace plenopiv::lightfield {
namespace {

TEST(FocusMeasure, OneLitPixelIsOneAndUniformLightIsOneOverN) {
  ImageF image(4, 5, 0.f);
  EXPECT_EQ(focus_measure(image), 0.0);  // black: no light to be concentrated
  image.at(2, 3) = 7.f;
  EXPECT_DOUBLE_EQ(focus_measure(image), 1.0);
  EXPECT_DOUBLE_EQ(focus_measure(ImageF(4, 5, 3.f)), 1.0 / 20);
}

TEST(SharpestDepth, RefusesAnEmptyOrBackwardSweep) {
  const LightField none{};
  EXPECT_THROW(sharpest_depth_mm(none, small_camera(), -1, 1, 0), InputError);
  EXPECT_THROW(sharpest_depth_mm(none, small_camera(), 1, -1, 0.5), InputError);
}

}  // namespace
}  // namespace plenopiv::lightfield
