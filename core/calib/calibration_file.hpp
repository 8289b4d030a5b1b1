// The calibration file (HDF5, readable with h5py): lens centres, lattice, residuals, white correction.
#pragma once

#include <array>
#include <filesystem>
#include <optional>

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
//   /status            uint8   [ny][nx]     0 missing (not on the sensor: lattice used), 1 measured,
//                                            2 rejected (flawed: lattice used), 3 partial (cut by the
//                                            sensor edge: lattice used), 4 lattice (the fitted lattice
//                                            is the better centre)
//   /measured_px       float64 [ny][nx][2]  each lens's own measurement, pixels; NaN if none
//   /uncertainty_px    float64 [ny][nx]     its 1-sigma uncertainty per axis, pixels; NaN if none
//   /white_correction  float32 [height][width]  fig 15: 1 inside each microlens image, 0 outside
//   /lattice attributes (float64): layout (0 rect, 1 hex), count_x, count_y, spot_pitch_x_px,
//     spot_pitch_y_px, rotation_rad (counter-clockwise on the upright image), spot_offset_x_px,
//     spot_offset_y_px (spot lattice centre from the sensor centre), lens_pitch_x_mm, lens_pitch_y_mm,
//     lens_offset_x_mm, lens_offset_y_mm, rms_residual_px, max_residual_px, spots_found, lenses_measured,
//     lenses_lattice, lenses_partial, lenses_rejected, lenses_vignetted, centres_from (0 calibration image, 1 white),
//     measurement_scatter_px, array_scatter_px, distortion_degree, nominal_spot_pitch_px, pitch_ratio
//   /camera attributes (float64): sensor_width_px, sensor_height_px, pixel_pitch_mm,
//     image_distance_mm (s_i), microlens_focal_length_mm (f_l), optical_axis_given (0/1),
//     optical_axis_x_px, optical_axis_y_px (the frame's origin), camera_count_x, camera_count_y
//     (the camera file's lens counts; 0: not given)
//   /image attributes (float64): background, noise_sigma, threshold, hot_pixels
//   /white attributes (float64): fill, predicted_fill, measured_axis_x_px, measured_axis_y_px,
//     measured_axis_sigma_px (NaN: not measurable), black_level, calibration_frames, white_frames,
//     dark_frames
// Attributes and datasets after lenses_measured are optional on reading (files written before
// them load with defaults).
// Written atomically.
void write_calibration_h5(const std::filesystem::path& path, const Calibration& calibration);
// Reads the whole file back (InputError naming the file and the missing or malformed part).
Calibration read_calibration_h5(const std::filesystem::path& path);

// What the other modules need: the lens centres on the microlens plane and the white correction.
struct LoadedCalibration {
  optics::MicrolensArray lenses;
  ImageF white_correction;
  // The optical axis (column, row px) calibration measured, when the camera file gives none: the
  // lenses are in its frame, and the camera for them is camera_in_frame's.
  std::optional<std::array<double, 2>> measured_optical_axis_px;
};
// Loads a calibration file for `camera`; a file made for another sensor size, layout, s_i / f_l,
// or with other lens counts in the camera file (when this one gives counts), is an InputError
// saying which. Lens centres come out in `camera`'s frame (its optical axis, or the one the
// calibration measured when the camera file gives none): the spots stay where they were measured.
LoadedCalibration load_calibration(const std::filesystem::path& path, const optics::CameraModel& camera);
// The same for a calibration just made (its own frame).
LoadedCalibration loaded_calibration(Calibration calibration);
// The camera the calibration's lenses belong to: `camera` with the measured optical axis when
// the calibration has one and the camera file gives none, else `camera` itself.
optics::CameraModel camera_in_frame(const optics::CameraModel& camera, const LoadedCalibration& calibration);

}  // namespace plenopiv::calib
