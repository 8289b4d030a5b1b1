// A calibrated camera's stand-in for the benchmarks that render through an imperfect microlens
// array and process with it as the calibration, shared by bench_rotated_shear and
// bench_depth_response.
#pragma once

#include <array>
#include <numbers>

#include "core/calib/nominal_calibration.hpp"
#include "core/optics/camera_model.hpp"
#include "core/optics/microlens_array.hpp"
#include "core/sim/render.hpp"

namespace plenopiv::bench {

// The camera file's lattice rotated by `degrees`, offset by `offset_mm` on the sensor and each lens
// moved by Gaussian jitter of `jitter_mm` (a fixed seed), with the geometric white image of those
// lenses.
inline calib::LoadedCalibration simulated_calibration(const optics::CameraModel& camera, double degrees,
                                                      const std::array<double, 2>& offset_mm, double jitter_mm) {
  optics::Lattice lattice = optics::Lattice::nominal(camera);
  lattice.rotation_rad = degrees * std::numbers::pi / 180;
  lattice.offset_x_mm = offset_mm[0];
  lattice.offset_y_mm = offset_mm[1];
  calib::LoadedCalibration out;
  out.lenses = sim::jittered_array(lattice, jitter_mm, 5);
  out.white_correction = calib::geometric_white_image(camera, out.lenses);
  return out;
}

}  // namespace plenopiv::bench
