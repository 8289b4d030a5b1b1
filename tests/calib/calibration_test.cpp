// Calibration: spot centroids and the lattice fit against known spot positions, white correction,
// the calibration file (also read by h5py), and every refused input.
#include <gtest/gtest.h>
#include <tbb/global_control.h>

#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <numbers>
#include <vector>

#include "core/base/errors.hpp"
#include "core/calib/calibration.hpp"
#include "core/calib/calibration_file.hpp"
#include "core/optics/camera_file.hpp"
#include "tests/calib/spot_render.hpp"
#include "tests/support/cameras.hpp"
#include "tests/support/temp_dir.hpp"

namespace plenopiv::calib {
namespace {

using testing_support::render_calibration;
using testing_support::RenderedSpots;
using testing_support::SpotScene;

using testing_support::small_camera;

// The figure scene: rotated 0.5 deg, offset, +-1 um per-lens jitter, noise on.
SpotScene figure_scene() {
  SpotScene s;
  s.rotation_deg = 0.5;
  s.offset_x_mm = 0.011;
  s.offset_y_mm = -0.007;
  s.jitter_mm = 0.001;
  s.noise_sigma = 8;
  s.vignetting = 0.3;
  s.seed = 7;
  return s;
}

struct CentreError {
  double rms = 0;
  double max = 0;
  int measured = 0;
};

CentreError centre_error(const Calibration& cal, const RenderedSpots& truth) {
  CentreError e;
  double sum = 0;
  for (std::size_t k = 0; k < cal.spots_px.size(); ++k) {
    if (cal.status[k] != LensStatus::measured) continue;
    const double d =
        std::hypot(cal.spots_px[k][0] - truth.true_spots_px[k][0], cal.spots_px[k][1] - truth.true_spots_px[k][1]);
    sum += d * d;
    e.max = std::max(e.max, d);
    ++e.measured;
  }
  e.rms = std::sqrt(sum / std::max(e.measured, 1));
  return e;
}

std::string error_of(const optics::CameraModel& cam, const ImageF& image) {
  try {
    calibrate(cam, image);
  } catch (const InputError& e) {
    return e.what();
  }
  return "";
}

TEST(Calibrate, RectFigureSceneCentresWithinBound) {
  const auto cam = small_camera("rect");
  const RenderedSpots truth = render_calibration(cam, figure_scene());
  const Calibration cal = calibrate(cam, truth.image);
  const CentreError e = centre_error(cal, truth);
  std::cout << "rect centre error rms " << e.rms << " px max " << e.max << " px, residual rms " << cal.rms_residual_px
            << " px\n";
  // Centres at noise 8 on a peak of 2000 with 30 % vignetting.
  EXPECT_LT(e.rms, 0.02) << "measured 0.0130 px (max 0.037)";
  EXPECT_EQ(e.measured, 2500);
  EXPECT_NEAR(cal.spot_lattice.rotation_rad, 0.5 * std::numbers::pi / 180, 2e-4);
  const double scale = 1 + cam.microlens().focal_length_mm / cam.image_distance_mm();
  EXPECT_NEAR(cal.spot_lattice.pitch_x_mm / (0.125 * scale), 1.0, 2e-4);
  EXPECT_NEAR(cal.spot_lattice.offset_x_mm, 0.011 * scale, 3e-4);
  EXPECT_NEAR(cal.spot_lattice.offset_y_mm, -0.007 * scale, 3e-4);
  // The jitter (+-1 um on the lens = +-0.136 px on the spot) is what the residuals show.
  EXPECT_GT(cal.rms_residual_px, 0.05);
  EXPECT_LT(cal.rms_residual_px, 0.15);
}

TEST(Calibrate, HexFigureSceneCentresWithinBound) {
  const auto cam = small_camera("hex");
  const RenderedSpots truth = render_calibration(cam, figure_scene());
  const Calibration cal = calibrate(cam, truth.image);
  const CentreError e = centre_error(cal, truth);
  std::cout << "hex centre error rms " << e.rms << " px max " << e.max << " px\n";
  EXPECT_LT(e.rms, 0.02) << "measured 0.0130 px (max 0.037)";
  EXPECT_GE(e.measured, 2450);
  EXPECT_NEAR(cal.spot_lattice.rotation_rad, 0.5 * std::numbers::pi / 180, 2e-4);
}

// Lens centres (microlens plane) against the true jittered centres: the spot error scaled back.
TEST(Calibrate, LensCentresAreSpotsScaledBackToTheMicrolensPlane) {
  const auto cam = small_camera("rect");
  SpotScene scene = figure_scene();
  scene.noise_sigma = 0;
  const RenderedSpots truth = render_calibration(cam, scene);
  const Calibration cal = calibrate(cam, truth.image);
  const optics::MicrolensArray lenses = cal.microlens_array();
  const double s_i = cam.image_distance_mm(), f_l = cam.microlens().focal_length_mm;
  const auto& sensor = cam.sensor();
  double worst = 0;
  for (std::size_t k = 0; k < lenses.centres_mm.size(); ++k) {
    const double tx =
        optics::spot_to_lens_centre_mm(optics::column_to_sensor_mm(sensor, truth.true_spots_px[k][0]), s_i, f_l);
    const double ty =
        optics::spot_to_lens_centre_mm(optics::row_to_sensor_mm(sensor, truth.true_spots_px[k][1]), s_i, f_l);
    worst = std::max(worst, std::hypot(lenses.centres_mm[k][0] - tx, lenses.centres_mm[k][1] - ty));
  }
  EXPECT_LT(worst, 0.03 * sensor.pixel_pitch_mm);
  EXPECT_NEAR(lenses.lattice.pitch_x_mm, 0.125, 1e-5);
  EXPECT_NEAR(lenses.lattice.offset_x_mm, 0.011, 2e-4);
}

struct Robustness {
  const char* layout;
  double rotation_deg;
  double pitch_scale;
};

class CalibrateRobust : public ::testing::TestWithParam<Robustness> {};

// Rotation +-2 deg, pitch +-3 %, strong vignetting, dim and missing edge spots, hot pixels, noise.
TEST_P(CalibrateRobust, RecoversLatticeAndCentres) {
  const Robustness r = GetParam();
  const auto cam = small_camera(r.layout);
  SpotScene scene = figure_scene();
  scene.rotation_deg = r.rotation_deg;
  scene.pitch_scale = r.pitch_scale;
  scene.vignetting = 0.8;
  scene.missing_edge_fraction = 0.3;
  scene.hot_pixels = 300;
  scene.noise_sigma = 5;
  const RenderedSpots truth = render_calibration(cam, scene);
  const Calibration cal = calibrate(cam, truth.image);
  const double scale = 1 + cam.microlens().focal_length_mm / cam.image_distance_mm();
  EXPECT_NEAR(cal.spot_lattice.rotation_rad, r.rotation_deg * std::numbers::pi / 180, 3e-4);
  EXPECT_NEAR(cal.spot_lattice.pitch_x_mm / (0.125 * r.pitch_scale * scale), 1.0, 3e-4);
  EXPECT_NEAR(cal.spot_lattice.pitch_y_mm / (cam.row_pitch_mm() * r.pitch_scale * scale), 1.0, 3e-4);
  // Every lens is where the truth has it: measured lenses at their spot, the rest on the lattice.
  double worst_all = 0;
  for (std::size_t k = 0; k < cal.spots_px.size(); ++k) {
    const double d =
        std::hypot(cal.spots_px[k][0] - truth.true_spots_px[k][0], cal.spots_px[k][1] - truth.true_spots_px[k][1]);
    EXPECT_LT(d, 0.5) << "lens " << k << " status " << int(cal.status[k]);
    worst_all = std::max(worst_all, d);
  }
  const CentreError e = centre_error(cal, truth);
  std::cout << r.layout << " rot " << r.rotation_deg << " pitch " << r.pitch_scale << ": centre error rms " << e.rms
            << " px, worst lens (any status) " << worst_all << " px, measured " << e.measured << "\n";
  EXPECT_LT(e.rms, 0.02) << "measured 0.011-0.013 px";
  int lit = 0;  // spots wholly on the sensor
  for (std::size_t k = 0; k < truth.lit.size(); ++k) {
    const auto& q = truth.true_spots_px[k];
    lit += truth.lit[k] && q[0] > 4 && q[1] > 4 && q[0] < 845 && q[1] < 845;
  }
  EXPECT_GE(e.measured, lit - 30);  // hot pixels next to a spot may get a lens rejected
  EXPECT_GT(cal.image_stats.hot_pixels, 250);
}

INSTANTIATE_TEST_SUITE_P(RotationPitchLayout, CalibrateRobust,
                         ::testing::Values(Robustness{"rect", 2.0, 1.03}, Robustness{"rect", -2.0, 0.97},
                                           Robustness{"hex", 2.0, 0.97}, Robustness{"hex", -2.0, 1.03}));

TEST(Calibrate, SameResultAtOneAndTwoThreads) {
  const auto cam = small_camera("hex");
  const RenderedSpots truth = render_calibration(cam, figure_scene());
  Calibration one, two;
  {
    tbb::global_control c(tbb::global_control::max_allowed_parallelism, 1);
    one = calibrate(cam, truth.image);
  }
  {
    tbb::global_control c(tbb::global_control::max_allowed_parallelism, 2);
    two = calibrate(cam, truth.image);
  }
  EXPECT_EQ(one.spots_px, two.spots_px);
  EXPECT_EQ(one.spot_lattice.rotation_rad, two.spot_lattice.rotation_rad);
}

TEST(Calibrate, RefusesWrongSizeNoSpotsAndNoLattice) {
  const auto cam = small_camera("rect");
  EXPECT_NE(error_of(cam, ImageF(800, 850, 100)).find("800 x 850 pixels, the camera file's sensor is 850 x 850"),
            std::string::npos);
  EXPECT_NE(error_of(cam, ImageF(850, 850, 100)).find("found 0 spots, expected about 2 500"), std::string::npos);

  // 312 spots only (a quarter-size window of the array lit).
  SpotScene few = figure_scene();
  RenderedSpots r = render_calibration(cam, few);
  ImageF cropped(850, 850, 100);
  for (int y = 0; y < 850; ++y)
    for (int x = 0; x < 850; ++x)
      if (x < 240 && y < 230) cropped.at(x, y) = r.image.at(x, y);
  const std::string msg = error_of(cam, cropped);
  EXPECT_NE(msg.find("spots, expected about 2 500"), std::string::npos) << msg;

  // Spots at random places: as many as lenses, but no lattice.
  SpotScene scattered = figure_scene();
  scattered.jitter_mm = 0.06;  // half a pitch
  const std::string lattice_msg = error_of(cam, render_calibration(cam, scattered).image);
  EXPECT_NE(lattice_msg.find("lattice"), std::string::npos) << lattice_msg;

  ImageF bad(850, 850, 100);
  bad.at(3, 4) = std::nanf("");
  EXPECT_NE(error_of(cam, bad).find("pixel (3, 4)"), std::string::npos);
  EXPECT_NE(error_of(cam, bad).find("must be finite"), std::string::npos);
}

TEST(WhiteCorrection, OneInsideEachLensImageZeroInTheGaps) {
  const auto cam = small_camera("rect");
  SpotScene scene = figure_scene();
  scene.vignetting = 0.6;
  const RenderedSpots truth = render_calibration(cam, scene);
  const Calibration cal = calibrate(cam, truth.image);
  const ImageF white = testing_support::render_white(cam, truth, scene, 0.8);
  const ImageF corr = make_white_correction(cal, white, scene.background);
  int checked = 0;
  for (std::size_t k = 0; k < cal.spots_px.size(); k += 7) {
    const auto& q = truth.true_spots_px[k];
    EXPECT_NEAR(corr.at(int(std::lround(q[0])), int(std::lround(q[1]))), 1.0f, 1e-3) << k;
    ++checked;
  }
  EXPECT_GT(checked, 300);
  // The corner gap between four lens images receives no light.
  const int nx = cal.spot_lattice.count_x;
  const auto& a = truth.true_spots_px[std::size_t(20) * nx + 20];
  const auto& b = truth.true_spots_px[std::size_t(21) * nx + 21];
  EXPECT_NEAR(corr.at(int(std::lround(0.5 * (a[0] + b[0]))), int(std::lround(0.5 * (a[1] + b[1])))), 0.0f, 1e-6);
  // Beyond the array's edge: nothing.
  EXPECT_EQ(corr.at(0, 0), 0.0f);
  EXPECT_THROW(make_white_correction(cal, ImageF(10, 10, 1), 0), InputError);
}

// Light outside a lens's image disk (diffraction halo, scatter) is not kept: the reconstruction's
// weights apply the circular aperture through the white correction's zeros (docs/recon.md, "White
// correction from a measured white image"). A white image lit everywhere, even the gaps:
TEST(WhiteCorrection, ZeroOutsideEachLensImageDiskAndTheRemovedLightReported) {
  const auto cam = small_camera("rect");
  const SpotScene scene;
  const RenderedSpots truth = render_calibration(cam, scene);
  Calibration cal = calibrate(cam, truth.image);
  EXPECT_NEAR(cal.microlens_image_diameter_px, cam.microlens_image_diameter_px(), 1e-12);
  const double r = 0.5 * cal.microlens_image_diameter_px;
  double outside = 0;
  const ImageF corr = make_white_correction(cal, ImageF(850, 850, 100.0f), 0.0, &outside);
  // Each pixel's distance to its nearest spot (within 12 px; farther means beyond the array).
  std::vector<double> nearest(850 * 850, 1e9);
  for (const auto& q : cal.spots_px) {
    for (int y = std::max(0, int(q[1]) - 12); y <= std::min(849, int(q[1]) + 12); ++y) {
      for (int x = std::max(0, int(q[0]) - 12); x <= std::min(849, int(q[0]) + 12); ++x) {
        double& d = nearest[std::size_t(y) * 850 + std::size_t(x)];
        d = std::min(d, std::hypot(q[0] - x, q[1] - y));
      }
    }
  }
  int inside_checked = 0, outside_checked = 0;
  for (int y = 0; y < 850; ++y) {
    for (int x = 0; x < 850; ++x) {
      const double d = nearest[std::size_t(y) * 850 + std::size_t(x)];
      if (d < r - 0.71) {  // the whole pixel inside the disk
        EXPECT_EQ(corr.at(x, y), 1.0f) << x << ", " << y;
        ++inside_checked;
      } else if (d > r + 0.71 && d < 12) {  // the whole pixel outside, between lenses
        EXPECT_EQ(corr.at(x, y), 0.0f) << x << ", " << y;
        ++outside_checked;
      }
    }
  }
  EXPECT_GT(inside_checked, 50 * 50 * 150);
  EXPECT_GT(outside_checked, 50 * 50 * 20);
  // The lit share outside the disks: 1 - pi r^2 / pitch^2 = 22 % of each lens's cell, less the
  // rim pixels that overlap the disk.
  std::cout << "measured: light outside the disks " << outside << "\n";
  EXPECT_GT(outside, 0.10) << "measured 0.1315";
  EXPECT_LT(outside, 0.22) << "measured 0.1315";
  // A calibration read from a file carries no image diameter: refused, not guessed.
  cal.microlens_image_diameter_px = 0;
  EXPECT_THROW(make_white_correction(cal, ImageF(850, 850, 100.0f), 0.0), InputError);
}

TEST(CalibrationFile, RoundTripH5pyAndLoader) {
  const auto cam = small_camera("hex");
  const SpotScene scene = figure_scene();
  const RenderedSpots truth = render_calibration(cam, scene);
  Calibration cal = calibrate(cam, truth.image);
  cal.white_correction = make_white_correction(cal, testing_support::render_white(cam, truth, scene, 0.8), 100);
  const auto dir = testing_support::temp_dir("calib");
  const auto file = dir / "cal.h5";
  write_calibration_h5(file, cal);

  const Calibration back = read_calibration_h5(file);
  EXPECT_EQ(back.spots_px, cal.spots_px);
  EXPECT_EQ(back.status, cal.status);
  EXPECT_EQ(back.spot_lattice.rotation_rad, cal.spot_lattice.rotation_rad);
  EXPECT_EQ(back.white_correction.pixels, cal.white_correction.pixels);

  const LoadedCalibration loaded = load_calibration(file, cam);
  const optics::MicrolensArray expect = cal.microlens_array();
  EXPECT_EQ(loaded.lenses.centres_mm, expect.centres_mm);
  EXPECT_EQ(loaded.lenses.lattice.layout, optics::LensletLayout::hex);
  EXPECT_EQ(loaded.white_correction.width, 850);
  EXPECT_THROW(load_calibration(file, small_camera("rect")), InputError);

  // Python reads the layout the docs give.
  const auto script = dir / "read.py";
  std::ofstream(script) << "import h5py, numpy as np\n"
                           "f = h5py.File('"
                        << file.string()
                        << "', 'r')\n"
                           "assert f['spots_px'].shape == (50, 49, 2)\n"
                           "assert f['lens_centres_mm'].shape == (50, 49, 2)\n"
                           "assert f['white_correction'].shape == (850, 850)\n"
                           "assert f['status'].dtype == np.uint8\n"
                           "assert f['lattice'].attrs['layout'] == 1\n"
                           "assert abs(f['lattice'].attrs['lens_pitch_x_mm'] - 0.125) < 1e-4\n"
                           "print('ok', float(f['lattice'].attrs['rms_residual_px']))\n";
  EXPECT_EQ(std::system(("/usr/bin/python3 " + script.string() + " > " + (dir / "out.txt").string()).c_str()), 0);
  std::filesystem::remove_all(dir);
}

}  // namespace
}  // namespace plenopiv::calib
