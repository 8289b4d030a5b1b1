// Calibration on the simulator's images: centre error against its true (rotated, offset,
// jittered) lens centres with noise on, rect and hex, and the white correction of its white image.
#include <gtest/gtest.h>

#include <cmath>
#include <iostream>
#include <numbers>

#include "core/calib/calibration.hpp"
#include "core/optics/camera_file.hpp"
#include "core/sim/render.hpp"
#include "tests/support/cameras.hpp"

namespace plenopiv::calib {
namespace {

using testing_support::small_camera;

// The scene: array rotated 0.5 deg, offset, 1 um per-lens jitter; sensor noise on.
optics::MicrolensArray true_array(const optics::CameraModel& cam) {
  optics::Lattice l = optics::Lattice::nominal(cam);
  l.rotation_rad = 0.5 * std::numbers::pi / 180;
  l.offset_x_mm = 0.011;
  l.offset_y_mm = -0.007;
  return sim::jittered_array(l, 0.001, 5);
}

sim::SensorModel noisy_sensor() {
  sim::SensorModel s;
  s.electrons_per_ray = 5;
  s.shot_noise = true;
  s.read_noise_electrons = 10;
  s.dark_offset_dn = 100;
  return s;
}

ImageF to_float(const ImageU16& in) {
  ImageF out(in.width, in.height);
  for (std::size_t k = 0; k < in.size(); ++k) out.pixels[k] = in.pixels[k];
  return out;
}

class SimCalibration : public ::testing::TestWithParam<std::string> {};

TEST_P(SimCalibration, CentreErrorAgainstTheSimulatorsTrueCentres) {
  const auto cam = small_camera(GetParam());
  const auto array = true_array(cam);
  sim::TargetOptions target = sim::calibration_target();  // f/16
  target.rays_per_lens = 20000;
  target.sensor = noisy_sensor();
  const ImageF image = to_float(sim::render_target(cam, array, target, 11).image);
  const Calibration cal = calibrate(cam, image);
  const double s_i = cam.image_distance_mm(), f_l = cam.microlens().focal_length_mm;
  double sum = 0, worst = 0;
  int n = 0;
  for (std::size_t k = 0; k < array.centres_mm.size(); ++k) {
    if (cal.status[k] != LensStatus::measured) continue;
    const double col =
        optics::sensor_mm_to_column(cam.sensor(), optics::lens_centre_to_spot_mm(array.centres_mm[k][0], s_i, f_l));
    const double row =
        optics::sensor_mm_to_row(cam.sensor(), optics::lens_centre_to_spot_mm(array.centres_mm[k][1], s_i, f_l));
    const double d = std::hypot(cal.spots_px[k][0] - col, cal.spots_px[k][1] - row);
    sum += d * d;
    worst = std::max(worst, d);
    ++n;
  }
  const double rms = std::sqrt(sum / n);
  std::cout << GetParam() << ": centre error " << rms << " px rms, " << worst << " px max over " << n
            << " measured lenses; lattice residual " << cal.rms_residual_px << " px rms\n";
  // Centres against the simulator's true spots; the issue asks <= 0.05 px.
  EXPECT_LT(rms, 0.02) << "measured 0.0103 px (rect), 0.0104 px (hex)";
  EXPECT_GE(n, int(array.centres_mm.size()) - 10);
  EXPECT_NEAR(cal.spot_lattice.rotation_rad, 0.5 * std::numbers::pi / 180, 2e-5);
  // Lens centres on the microlens plane: the same error scaled back by 1 / (1 + f_l/s_i).
  const optics::MicrolensArray lenses = cal.microlens_array();
  double lens_sum = 0;
  for (std::size_t k = 0; k < array.centres_mm.size(); ++k) {
    if (cal.status[k] != LensStatus::measured) continue;
    lens_sum += std::pow(
        std::hypot(lenses.centres_mm[k][0] - array.centres_mm[k][0], lenses.centres_mm[k][1] - array.centres_mm[k][1]),
        2);
  }
  EXPECT_LT(std::sqrt(lens_sum / n), 0.02 * cam.sensor().pixel_pitch_mm);
}

INSTANTIATE_TEST_SUITE_P(Layouts, SimCalibration, ::testing::Values("rect", "hex"));

TEST(SimWhiteCorrection, OneAtTheLensImageCentresZeroBetweenThem) {
  const auto cam = small_camera("rect");
  const auto array = true_array(cam);
  sim::TargetOptions target = sim::calibration_target();
  target.rays_per_lens = 2000;
  target.sensor = noisy_sensor();
  target.sensor.electrons_per_ray = 20;
  const Calibration cal = calibrate(cam, to_float(sim::render_target(cam, array, target, 11).image));
  sim::TargetOptions white = sim::white_target();
  white.rays_per_lens = 5000;
  white.sensor = noisy_sensor();
  const ImageF corr =
      make_white_correction(cal, to_float(sim::render_target(cam, array, white, 12).image), cal.image_stats.background);
  double centre_sum = 0;
  int n = 0;
  for (std::size_t k = 0; k < cal.spots_px.size(); ++k) {
    centre_sum += corr.at(int(std::lround(cal.spots_px[k][0])), int(std::lround(cal.spots_px[k][1])));
    ++n;
  }
  EXPECT_NEAR(centre_sum / n, 1.0, 0.05);
  // The corners between four round lens images receive no light: on average (each one pixel is
  // read noise over ~110 electrons of white signal, about 0.1 on its own) they are dark.
  double corner_sum = 0;
  int corners = 0;
  for (int j = 0; j + 1 < 50; ++j) {
    for (int i = 0; i + 1 < 50; ++i) {
      const auto& a = cal.spots_px[std::size_t(j) * 50 + i];
      const auto& b = cal.spots_px[std::size_t(j + 1) * 50 + i + 1];
      corner_sum += corr.at(int(std::lround(0.5 * (a[0] + b[0]))), int(std::lround(0.5 * (a[1] + b[1]))));
      ++corners;
    }
  }
  std::cout << "white correction: " << centre_sum / n << " at the lens image centres, " << corner_sum / corners
            << " at the corners between them\n";
  EXPECT_LT(corner_sum / corners, 0.05);
  EXPECT_EQ(corr.at(0, 0), 0.0f);
}

}  // namespace
}  // namespace plenopiv::calib
