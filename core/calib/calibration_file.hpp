// The calibration file (HDF5, readable with h5py): lens centres, lattice, residuals, white correction.
#pragma once

#include <filesystem>

#include "core/base/image.hpp"
#include "core/calib/calibration.hpp"
#include "core/optics/camera_model.hpp"
#include "core/optics/microlens_array.hpp"

namespace plenopiv::calib {

// Layout (docs/calibration.md, "Calibration file"); ny, nx = microlens rows, lenses per row:
//   /spots_px          float64 [ny][nx][2]  (column, row) of each lens's calibration spot, pixels
//                                            (integer = pixel centre); lattice position if not measured
//   /lens_centres_mm   float64 [ny][nx][2]  (x, y) lens centres on the microlens plane, mm, origin at
//                                            the sensor centre (spot_to_lens_centre_mm of /spots_px)
//   /residuals_px      float64 [ny][nx][2]  measured spot minus fitted lattice, pixels (0 if missing)
//   /status            uint8   [ny][nx]     0 missing (lattice used), 1 measured, 2 rejected outlier
//   /white_correction  float32 [height][width]  fig 15: 1 inside each microlens image, 0 outside
//   /lattice attributes (float64): layout (0 rect, 1 hex), count_x, count_y, spot_pitch_x_px,
//     spot_pitch_y_px, rotation_rad (counter-clockwise on the upright image), spot_offset_x_px,
//     spot_offset_y_px (spot lattice centre from the sensor centre), lens_pitch_x_mm, lens_pitch_y_mm,
//     lens_offset_x_mm, lens_offset_y_mm, rms_residual_px, max_residual_px, spots_found, lenses_measured
//   /camera attributes (float64): sensor_width_px, sensor_height_px, pixel_pitch_mm,
//     image_distance_mm (s_i), microlens_focal_length_mm (f_l)
//   /image attributes (float64): background, noise_sigma, threshold, hot_pixels
// Written atomically.
void write_calibration_h5(const std::filesystem::path& path, const Calibration& calibration);
// Reads the whole file back (InputError naming the file and the missing or malformed part).
Calibration read_calibration_h5(const std::filesystem::path& path);

// What the other modules need: the lens centres on the microlens plane and the white correction.
struct LoadedCalibration {
  optics::MicrolensArray lenses;
  ImageF white_correction;
};
// Loads a calibration file for `camera`; a file made for another sensor size, lens count,
// layout or s_i / f_l is an InputError saying which.
LoadedCalibration load_calibration(const std::filesystem::path& path, const optics::CameraModel& camera);

}  // namespace plenopiv::calib
