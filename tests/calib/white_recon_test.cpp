// Reconstruction and correlation from a white-only calibration: a known displacement through
// process_pair comes back as it does with the stopped-down calibration, for an array that is
// rotated (resampled onto an axis-aligned lattice) and one whose pitch the camera file has wrong.
#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <iostream>
#include <numbers>
#include <vector>

#include "core/base/yaml_access.hpp"
#include "core/calib/calibration.hpp"
#include "core/process/process.hpp"
#include "core/sim/particles.hpp"
#include "core/sim/render.hpp"
#include "tests/support/cameras.hpp"
#include "tests/support/mean_displacement.hpp"
#include "tests/support/small_shift_pair.hpp"

namespace plenopiv {
namespace {

ImageF to_float(const ImageU16& in) {
  ImageF out(in.width, in.height);
  for (std::size_t k = 0; k < in.size(); ++k) out.pixels[k] = in.pixels[k];
  return out;
}

struct Shift {
  std::array<double, 3> mm{};
  std::string note;
};

// The small camera; particles moved by (0.1, -0.05, 0.25) mm; the pair processed with lenses and
// white correction from a calibration of `truth` made from its images.
Shift processed_shift(const optics::MicrolensArray& truth, bool white_only) {
  const optics::CameraModel camera = testing_support::small_camera();
  const process::ProcessSettings s = testing_support::small_shift_settings("white_recon.yaml");
  sim::SensorModel sensor;
  sensor.electrons_per_ray = 20;
  sensor.shot_noise = true;
  sensor.read_noise_electrons = 10;
  sensor.dark_offset_dn = 100;
  calib::CalibrationFrames frames;
  sim::TargetOptions white = sim::white_target();
  white.rays_per_lens = 30000;
  white.sensor = sensor;
  frames.white = to_float(sim::render_target(camera, truth, white, 12).image);
  frames.dark = to_float(sim::apply_sensor(ImageF(850, 850, 0.0f), sensor, 13));
  if (!white_only) {
    sim::TargetOptions spots = sim::calibration_target();
    spots.sensor = sensor;
    frames.calibration = to_float(sim::render_target(camera, truth, spots, 11).image);
  }
  const calib::Calibration cal = calib::calibrate_camera(camera, frames);
  EXPECT_EQ(cal.source, white_only ? calib::CentreSource::white : calib::CentreSource::spots);

  const testing_support::FramePair frames_ab = testing_support::small_shift_pair(camera, truth, {0.1, -0.05, 0.25});
  const process::PairOperator op(camera, cal.microlens_array(), cal.white_correction, s);
  const auto r = process::process_pair(op, frames_ab.a, frames_ab.b, s);
  const testing_support::MeanDisplacement m = testing_support::mean_displacement(r.correlation.field);
  EXPECT_GT(m.valid, r.correlation.field.grid.count() / 2);
  return {m.mm, r.lattice_note};
}

class WhiteOnlyReconstruction : public ::testing::TestWithParam<double> {};

TEST_P(WhiteOnlyReconstruction, DisplacementAsWithTheStoppedDownCalibration) {
  const double pitch_scale = GetParam();
  const optics::CameraModel camera = testing_support::small_camera();
  optics::Lattice l = optics::Lattice::nominal(camera);
  l.rotation_rad = 0.3 * std::numbers::pi / 180;
  l.offset_x_mm = 0.011;
  l.offset_y_mm = -0.007;
  l.pitch_x_mm *= pitch_scale;
  l.pitch_y_mm *= pitch_scale;
  const optics::MicrolensArray truth = sim::jittered_array(l, 0.001, 5);
  const Shift spots = processed_shift(truth, false);
  const Shift white = processed_shift(truth, true);
  std::cout << "measured: array pitch x " << pitch_scale << ": mean displacement " << white.mm[0] << " " << white.mm[1]
            << " " << white.mm[2] << " mm from the white alone, " << spots.mm[0] << " " << spots.mm[1] << " "
            << spots.mm[2] << " mm from the stopped-down image (truth 0.1 -0.05 0.25)\n  " << white.note << "\n";
  EXPECT_NE(white.note.find("resampled onto an axis-aligned lattice"), std::string::npos) << white.note;
  for (int k = 0; k < 3; ++k) {
    EXPECT_NEAR(white.mm[std::size_t(k)], spots.mm[std::size_t(k)], 0.01) << "axis " << k << "; measured within 0.005";
  }
  EXPECT_NEAR(white.mm[0], 0.1, 0.01) << "measured 0.104";
  EXPECT_NEAR(white.mm[1], -0.05, 0.01) << "measured -0.044";
  EXPECT_NEAR(white.mm[2], 0.25, 0.05) << "measured 0.253";
}

// The array 0.9 % coarser than the camera file says: the white alone finds the pitch, and the
// reconstruction reads every spot where it is.
INSTANTIATE_TEST_SUITE_P(ArrayPitch, WhiteOnlyReconstruction, ::testing::Values(1.009));

}  // namespace
}  // namespace plenopiv
