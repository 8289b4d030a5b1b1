// Calibration from a white image alone, on the simulator's cameras as mounted: arrays that
// overfill the sensor and are cut by its edges, rotated, off the optical axis, at whole and
// non-whole pitches, rect and hex, with dust and cat's-eye vignetting; centre errors and found
// fractions against the truth, and what the camera file gets wrong said and corrected.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <filesystem>
#include <iostream>
#include <numbers>

#include "core/base/errors.hpp"
#include "core/calib/calibration.hpp"
#include "core/calib/calibration_file.hpp"
#include "core/optics/camera_file.hpp"
#include "core/optics/microlens_array.hpp"
#include "tests/calib/white_cases.hpp"
#include "tests/support/temp_dir.hpp"

namespace plenopiv::calib {
namespace {

using testing_support::WhiteCase;

Calibration calibrate_white(const testing_support::WhiteScene& scene) {
  CalibrationFrames frames;
  frames.white = scene.white;
  frames.dark = scene.dark;
  return calibrate_camera(scene.camera, frames);
}

std::string error_of(const testing_support::WhiteScene& scene) {
  try {
    calibrate_white(scene);
  } catch (const InputError& e) {
    return e.what();
  }
  return "";
}

bool has_note(const Calibration& cal, const std::string& text) {
  for (const auto& n : cal.notes)
    if (n.find(text) != std::string::npos) return true;
  return false;
}

// The camera with the lens barrel cutting the micro-images into cat's eyes and its optical
// axis 7 px off the sensor centre, not in the camera file (80 % of the micro-images cut).
WhiteCase vignetted_axis_unknown() {
  return WhiteCase{.name = "issue_camera_vignetted_axis_unknown",
                   .rotation_deg = -0.13,
                   .axis_offset_px = {6, -4},
                   .dust = 6,
                   .vignetting_stop_mm = 6,
                   .rays_per_px = 30,
                   .bit_depth = 8,
                   .seed = 7};
}

// The targets: whole lenses' centres within 0.05 px rms of the truth, 99 % of them found.
// The white images carry more noise than a real camera's (100 rays per pixel: 10 % per pixel at
// the 48.2 and 13.07 px pitches, 1000 at 7.66 px: 3 %; an 8-bit camera near full well has ~1 %).
class WhiteOnly : public ::testing::TestWithParam<WhiteCase> {};

TEST_P(WhiteOnly, CentresOfWholeLensesAgainstTheTruth) {
  const WhiteCase& c = GetParam();
  const auto scene = testing_support::render_white_scene(c);
  const Calibration cal = calibrate_white(scene);
  const auto e = testing_support::centre_errors(scene, cal);
  std::cout << "measured: " << c.name << ": centre error " << e.rms_px << " px rms (max " << e.max_px << ") over "
            << e.found << " of " << e.whole << " whole lenses found (" << 100 * e.found_fraction() << " %)\n"
            << describe(cal);
  EXPECT_LT(e.rms_px, 0.05) << "measured values are printed above";
  EXPECT_GE(e.found_fraction(), 0.99);
  EXPECT_NEAR(cal.spot_lattice.rotation_rad, c.rotation_deg * std::numbers::pi / 180, 2e-4);
  EXPECT_NEAR(cal.spot_lattice.pitch_x_mm / c.pixel_pitch_mm / c.spot_pitch_px, 1.0, 2e-4);
  // The fill from the light each lens passes, against the simulator's aperture.
  EXPECT_NEAR(cal.fill / scene.truth_camera.predicted_fill(), 1.0, 0.02) << cal.fill;
  EXPECT_EQ(cal.source, CentreSource::white);
  if (c.vignetting_stop_mm > 0) {
    // The axis from the cat's eye: where the simulator's optical axis meets the sensor.
    const auto axis = scene.truth_camera.optical_axis_px();
    ASSERT_TRUE(std::isfinite(cal.measured_axis_px[0]));
    const double off = std::hypot(cal.measured_axis_px[0] - axis[0], cal.measured_axis_px[1] - axis[1]);
    std::cout << "measured: " << c.name << ": axis " << off << " px from the truth (sigma "
              << cal.measured_axis_sigma_px << " px)\n";
    EXPECT_LT(off, 3 * cal.measured_axis_sigma_px + 0.5);
    EXPECT_GT(cal.lenses_vignetted, 100);
    // Not in the camera file: the measured axis becomes the calibration's frame.
    EXPECT_TRUE(cal.axis_measured);
    EXPECT_TRUE(has_note(cal, "measured from the micro-images' cat's-eye vignetting")) << describe(cal);
  }
}

INSTANTIATE_TEST_SUITE_P(
    Cases, WhiteOnly,
    ::testing::Values(
        // The camera: 1280 x 960 8-bit, 300 um lenses over 6.45 um pixels = 48.2 px,
        // rotated -0.13 deg, its centre 6.5 px off the axis, overfilling the sensor, dust.
        WhiteCase{
            .name = "issue_camera_rect_48p2", .rotation_deg = -0.13, .dust = 6, .rays_per_px = 30, .bit_depth = 8},
        WhiteCase{.name = "hex_48p2_plus2deg_axis_off",
                  .layout = "hex",
                  .rotation_deg = 2,
                  .axis_offset_px = {6, -4},
                  .axis_in_camera_file = true,
                  .dust = 4,
                  .rays_per_px = 30,
                  .seed = 2},
        vignetted_axis_unknown(),
        WhiteCase{.name = "rect_13p07_plus2deg_jitter",
                  .spot_pitch_px = 13.07,
                  .width = 520,
                  .height = 400,
                  .pixel_pitch_mm = 0.0074,
                  .microlens_focal_mm = 0.5,
                  .image_distance_mm = 100,
                  .rotation_deg = 2,
                  .axis_offset_px = {6, 0},
                  .axis_in_camera_file = true,
                  .jitter_px = 0.1,
                  .dust = 3,
                  .seed = 3},
        WhiteCase{.name = "hex_13p07_minus2deg",
                  .layout = "hex",
                  .spot_pitch_px = 13.07,
                  .width = 520,
                  .height = 400,
                  .pixel_pitch_mm = 0.0074,
                  .microlens_focal_mm = 0.5,
                  .image_distance_mm = 100,
                  .rotation_deg = -2,
                  .dust = 3,
                  .seed = 4},
        // The limit of rotation, +-5 deg.
        WhiteCase{.name = "rect_13p07_minus5deg",
                  .spot_pitch_px = 13.07,
                  .width = 520,
                  .height = 400,
                  .pixel_pitch_mm = 0.0074,
                  .microlens_focal_mm = 0.5,
                  .image_distance_mm = 100,
                  .rotation_deg = -5,
                  .dust = 3,
                  .seed = 8},
        WhiteCase{.name = "hex_13p07_plus5deg_axis_off",
                  .layout = "hex",
                  .spot_pitch_px = 13.07,
                  .width = 520,
                  .height = 400,
                  .pixel_pitch_mm = 0.0074,
                  .microlens_focal_mm = 0.5,
                  .image_distance_mm = 100,
                  .rotation_deg = 5,
                  .axis_offset_px = {-6, 3},
                  .axis_in_camera_file = true,
                  .dust = 3,
                  .seed = 9},
        WhiteCase{.name = "rect_7p66_minus2deg_jitter",
                  .spot_pitch_px = 7.66,
                  .width = 400,
                  .height = 320,
                  .pixel_pitch_mm = 0.0074,
                  .microlens_focal_mm = 0.25,
                  .image_distance_mm = 100,
                  .rotation_deg = -2,
                  .jitter_px = 0.1,
                  .dust = 3,
                  .rays_per_px = 1000,
                  .seed = 5},
        WhiteCase{.name = "hex_7p66_plus2deg_axis_off",
                  .layout = "hex",
                  .spot_pitch_px = 7.66,
                  .width = 400,
                  .height = 320,
                  .pixel_pitch_mm = 0.0074,
                  .microlens_focal_mm = 0.25,
                  .image_distance_mm = 100,
                  .rotation_deg = 2,
                  .axis_offset_px = {-6, 3},
                  .axis_in_camera_file = true,
                  .dust = 3,
                  .rays_per_px = 1000,
                  .seed = 6}),
    [](const ::testing::TestParamInfo<WhiteCase>& info) { return info.param.name; });

// The optical axis measured from the cat's eye is the frame of everything made from the
// calibration: kept in the file, given to every consumer by load_calibration and camera_in_frame
// (the processing's operator among them), every spot where it was measured; a camera file that
// gives the axis overrides it.
TEST(WhiteCalibration, AMeasuredOpticalAxisIsTheFrameOfEveryConsumer) {
  const auto scene = testing_support::render_white_scene(vignetted_axis_unknown());
  ASSERT_FALSE(scene.camera.sensor().optical_axis_px);
  const Calibration cal = calibrate_white(scene);
  ASSERT_TRUE(cal.axis_measured) << describe(cal);
  ASSERT_TRUE(cal.sensor.optical_axis_px);
  const std::array<double, 2> axis = *cal.sensor.optical_axis_px;
  const std::array<double, 2> truth = scene.truth_camera.optical_axis_px();
  EXPECT_LT(std::hypot(axis[0] - truth[0], axis[1] - truth[1]), 3 * cal.measured_axis_sigma_px + 0.5)
      << "axis at " << axis[0] << ", " << axis[1] << "; truth " << truth[0] << ", " << truth[1];
  EXPECT_LT(testing_support::centre_errors(scene, cal).rms_px, 0.05);

  const auto file = testing_support::temp_dir("calib-axis") / "axis.h5";
  write_calibration_h5(file, cal);
  EXPECT_TRUE(read_calibration_h5(file).axis_measured);
  const LoadedCalibration loaded = load_calibration(file, scene.camera);
  ASSERT_TRUE(loaded.measured_optical_axis_px);
  EXPECT_EQ(*loaded.measured_optical_axis_px, axis);
  const optics::CameraModel framed = camera_in_frame(scene.camera, loaded);
  EXPECT_EQ(framed.optical_axis_px(), axis);
  // Every lens's spot, through the framed camera, where the calibration measured it.
  const double s_i = framed.image_distance_mm(), f_l = framed.microlens().focal_length_mm;
  ASSERT_EQ(loaded.lenses.centres_mm.size(), cal.spots_px.size());
  double worst = 0;
  for (std::size_t k = 0; k < cal.spots_px.size(); ++k) {
    const auto& c = loaded.lenses.centres_mm[k];
    worst = std::max(
        {worst,
         std::abs(optics::sensor_mm_to_column(framed.sensor(), optics::lens_centre_to_spot_mm(c[0], s_i, f_l)) -
                  cal.spots_px[k][0]),
         std::abs(optics::sensor_mm_to_row(framed.sensor(), optics::lens_centre_to_spot_mm(c[1], s_i, f_l)) -
                  cal.spots_px[k][1])});
  }
  EXPECT_LT(worst, 1e-6) << "px";
  EXPECT_EQ(loaded_calibration(cal).measured_optical_axis_px, loaded.measured_optical_axis_px);

  // A camera file that gives the axis is the frame, whatever the calibration measured.
  const LoadedCalibration given = load_calibration(file, scene.truth_camera);
  EXPECT_FALSE(given.measured_optical_axis_px);
  EXPECT_EQ(camera_in_frame(scene.truth_camera, given).optical_axis_px(), truth);
  std::filesystem::remove_all(file.parent_path());
}

WhiteCase small_case() {
  return WhiteCase{.name = "small",
                   .spot_pitch_px = 13.07,
                   .width = 520,
                   .height = 400,
                   .pixel_pitch_mm = 0.0074,
                   .microlens_focal_mm = 0.5,
                   .image_distance_mm = 100,
                   .rotation_deg = 1,
                   .seed = 11};
}

// The camera file's pitch 0.9 % short of the array's: said, and applied as the lens pitch, so that
// the lens centres (what refocusing and reconstruction read) put every spot where it is.
TEST(WhiteCalibration, APitchDisagreementIsSaidAndAppliedAsTheLensPitch) {
  WhiteCase c = small_case();
  c.camera_pitch_scale = 1 / 1.009;
  const auto scene = testing_support::render_white_scene(c);
  const Calibration cal = calibrate_white(scene);
  EXPECT_NEAR(cal.pitch_ratio, 1.009, 2e-4);
  EXPECT_TRUE(has_note(cal, "0.90 % more than the camera file's")) << describe(cal);
  EXPECT_TRUE(has_note(cal, "the lens centres follow the measurement")) << describe(cal);
  EXPECT_TRUE(has_note(cal, "microlens-to-sensor distance is")) << describe(cal);
  const optics::MicrolensArray lenses = cal.microlens_array();
  EXPECT_NEAR(lenses.lattice.pitch_x_mm / scene.truth_camera.microlens().pitch_mm, 1.0, 2e-4);
  EXPECT_LT(testing_support::centre_errors(scene, cal).rms_px, 0.05);
}

// Micro-images that overlap in the image are refused, with the measured fill and what to do.
TEST(WhiteCalibration, OverlappingMicroImagesAreRefusedWithTheMeasuredFill) {
  WhiteCase c = small_case();
  c.fill = 1.15;
  const std::string err = error_of(testing_support::render_white_scene(c));
  EXPECT_NE(err.find("white image: the micro-images overlap"), std::string::npos) << err;
  EXPECT_NE(err.find("% of the 13."), std::string::npos) << err;
  EXPECT_NE(err.find("stop the main lens down"), std::string::npos) << err;
}

// The same camera file with its lens pitch scaled (or its layout swapped).
optics::CameraModel edited(const optics::CameraModel& camera, double pitch_scale, const char* layout = nullptr) {
  optics::CameraSpec spec = camera.spec();
  spec.microlens.pitch_mm *= pitch_scale;
  if (layout)
    spec.microlens.layout = std::string(layout) == "hex" ? optics::LensletLayout::hex : optics::LensletLayout::rect;
  return optics::CameraModel(spec, "edited.yaml");
}

// A camera file far from the image: what the image shows, what the file says, which keys.
TEST(WhiteCalibration, AWrongPitchAFlatImageAndAWrongLayoutAreNamed) {
  auto scene = testing_support::render_white_scene(small_case());
  const optics::CameraModel right = scene.camera;
  scene.camera = edited(right, 2);
  std::string err = error_of(scene);
  EXPECT_NE(err.find("px from their nearest neighbours, the camera file puts micro-images 26.14 px apart"),
            std::string::npos)
      << err;
  EXPECT_NE(err.find("microlens.pitch_mm"), std::string::npos) << err;

  scene.camera = edited(right, 1.15);  // near enough to find the lattice, too far to be the camera file's
  err = error_of(scene);
  EXPECT_NE(err.find("lattice of 13.070 x 13.070 px, more than 10 % from the camera file's 15.030"), std::string::npos)
      << err;

  // The white read as a hex array's.
  scene.camera = edited(right, 1, "hex");
  err = error_of(scene);
  EXPECT_NE(err.find("microlens.layout"), std::string::npos) << err;

  scene.camera = right;
  const ImageF white = scene.white;
  scene.white = ImageF(white.width, white.height, 120.0f);
  const ImageF dark = scene.dark;
  scene.dark = ImageF();
  err = error_of(scene);
  EXPECT_NE(err.find("white image: found 0 micro-images, expected about"), std::string::npos) << err;
  EXPECT_NE(err.find("is this a white image through the microlens array"), std::string::npos) << err;
  // Sensor noise alone (a capped lens taken for a white): maxima, but no lattice.
  scene.white = dark;
  err = error_of(scene);
  EXPECT_NE(err.find("white image: "), std::string::npos) << err;
  EXPECT_NE(err.find("is this a white image through the microlens array"), std::string::npos) << err;

  // A hex white read with a camera file that says rect.
  WhiteCase c = small_case();
  c.layout = "hex";
  scene = testing_support::render_white_scene(c);
  scene.camera = edited(scene.camera, 1, "rect");
  err = error_of(scene);
  EXPECT_NE(err.find("as a hex array's"), std::string::npos) << err;
}

// Counts are "at least": the sensor showing more lenses than the camera file says is accepted and
// said; the calibration loads with that camera file, and one with other counts is refused.
TEST(WhiteCalibration, CountsAreAMinimumAndTheFileBelongsToItsCameraFile) {
  WhiteCase c = small_case();
  c.counts_in_camera_file = true;
  const auto scene = testing_support::render_white_scene(c);
  ASSERT_TRUE(scene.camera.counts_given());
  CalibrationFrames frames;
  frames.white = scene.white;
  frames.dark = scene.dark;
  Calibration cal = calibrate_camera(scene.camera, frames);
  EXPECT_GT(cal.spot_lattice.count_x, scene.camera.microlens().count_x);
  EXPECT_TRUE(has_note(cal, "more than the camera file's count_x x count_y")) << describe(cal);
  const auto file = testing_support::temp_dir("calib-white") / "white.h5";
  write_calibration_h5(file, cal);
  const LoadedCalibration loaded = load_calibration(file, scene.camera);
  EXPECT_EQ(loaded.lenses.lattice.count_x, cal.spot_lattice.count_x);
  const Calibration back = read_calibration_h5(file);
  EXPECT_EQ(back.source, CentreSource::white);
  EXPECT_EQ(back.camera_count_x, scene.camera.microlens().count_x);
  EXPECT_EQ(back.lenses_partial, cal.lenses_partial);
  EXPECT_EQ(back.status, cal.status);
  EXPECT_DOUBLE_EQ(back.fill, cal.fill);
  ASSERT_EQ(back.uncertainty_px.size(), cal.uncertainty_px.size());
  // Another camera file (other counts) is another camera.
  std::string yaml = optics::to_yaml(scene.camera.spec());
  const auto at = yaml.find("count_x: ");
  yaml.replace(at, yaml.find(',', at) - at, "count_x: 12");
  try {
    load_calibration(file, optics::parse_camera_yaml(yaml, "other.yaml"));
    ADD_FAILURE() << "loaded with other counts";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("calibrate again with this camera file"), std::string::npos) << e.what();
  }
  // Without counts the camera file takes any array.
  yaml = optics::to_yaml(scene.camera.spec());
  yaml.erase(yaml.find(", count_x: "), yaml.find(", layout") - yaml.find(", count_x: "));
  EXPECT_NO_THROW(load_calibration(file, optics::parse_camera_yaml(yaml, "no-counts.yaml")));
  std::filesystem::remove_all(file.parent_path());
}

// The stopped-down image stays the preferred source of the centres when given.
TEST(WhiteCalibration, TheStoppedDownImageIsPreferredWhenGiven) {
  const auto scene = testing_support::render_white_scene(small_case());
  CalibrationFrames frames;
  frames.white = scene.white;
  frames.dark = scene.dark;
  // A stopped-down frame: the white's micro-images shrunk to spots (the simulator at f/16).
  frames.calibration = testing_support::render_calibration_frame(small_case(), scene);
  const Calibration cal = calibrate_camera(scene.camera, frames);
  EXPECT_EQ(cal.source, CentreSource::spots);
  EXPECT_NE(describe(cal).find("the calibration (stopped-down) image"), std::string::npos);
  EXPECT_LT(testing_support::centre_errors(scene, cal).rms_px, 0.05);
  EXPECT_TRUE(std::isfinite(cal.fill));  // the white still gives the fill
}

}  // namespace
}  // namespace plenopiv::calib
