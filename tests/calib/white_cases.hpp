// Test support: simulated cameras as mounted (arrays overfilling the sensor, rotated, off-axis,
// dust) whose white images the calibration must read, with the simulator's true centres.
#pragma once

#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include "core/base/image.hpp"
#include "core/calib/calibration.hpp"
#include "core/optics/camera_model.hpp"
#include "core/optics/microlens_array.hpp"

namespace plenopiv::testing_support {

struct WhiteCase {
  std::string name;
  std::string layout = "rect";
  double spot_pitch_px = 48.2;  // micro-image pitch on the sensor
  int width = 1280, height = 960;
  double pixel_pitch_mm = 0.00645;
  double microlens_focal_mm = 18.6;
  double image_distance_mm = 512.4;  // s_i (M = -1: f_m = s_i / 2)
  double fill = 1.0;                 // lens pitch over the f-number-matched aperture: 1 = matched
  double rotation_deg = 0;
  std::array<double, 2> array_offset_px{6.5, -3.0};  // array centre from the optical axis
  std::array<double, 2> axis_offset_px{0, 0};        // optical axis from the sensor centre (given in the camera file)
  bool axis_in_camera_file = false;
  double jitter_px = 0;           // per-lens Gaussian jitter of the true centres (on the sensor)
  int dust = 0;                   // dust shadows
  double vignetting_stop_mm = 0;  // diameter of a stop halfway to the array (0: none)
  double rays_per_px = 100;       // white: rays per pixel of lens area
  double electrons_per_ray = 20;
  int bit_depth = 12;
  bool counts_in_camera_file = false;
  double camera_pitch_scale = 1;  // the camera file's lens pitch over the true one
  std::uint64_t seed = 1;
};

struct WhiteScene {
  optics::CameraModel camera;                   // as the user's camera file describes it
  optics::CameraModel truth_camera;             // as the simulator rendered it
  optics::MicrolensArray truth;                 // the true array (overfilling the sensor)
  std::vector<std::array<double, 2>> spots_px;  // true micro-image centres, per true lens
  std::vector<std::uint8_t> whole;              // micro-image wholly on the sensor
  ImageF white;                                 // one rendered white frame, counts
  ImageF dark;                                  // the sensor's dark frame (offset + read noise)
};

WhiteScene render_white_scene(const WhiteCase& c);
// The same array stopped down to f/16 (a calibration image), as counts.
ImageF render_calibration_frame(const WhiteCase& c, const WhiteScene& scene);

// The calibration against the truth: every whole lens matched to the calibrated lens whose centre
// lies within half a pixel of its true centre (found), and their centre errors.
struct CentreErrors {
  int whole = 0;
  int found = 0;
  double rms_px = 0;
  double max_px = 0;
  double found_fraction() const { return whole > 0 ? double(found) / whole : 0.0; }
};
CentreErrors centre_errors(const WhiteScene& scene, const calib::Calibration& cal);

}  // namespace plenopiv::testing_support
