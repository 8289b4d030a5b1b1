// The nominal calibration: the camera file's lens lattice and the geometric white image, what a
// camera is reconstructed with before (or without) a measured calibration.
#pragma once

#include "core/base/image.hpp"
#include "core/calib/calibration_file.hpp"
#include "core/optics/camera_model.hpp"
#include "core/optics/microlens_array.hpp"

namespace plenopiv::calib {

// The white-image correction of fig 15 from the camera model alone: per pixel, the fraction of
// its area inside the disk of diameter CameraModel::microlens_image_diameter_px() around the spot
// of each lens of `lenses` (1 inside a microlens image, 0 outside, fractions on the rim). The
// same disk make_white_correction keeps of a measured white image.
ImageF geometric_white_image(const optics::CameraModel& camera, const optics::MicrolensArray& lenses);

// The camera's nominal lattice (optics::Lattice::nominal: centred, not rotated) and its geometric
// white image.
LoadedCalibration nominal_calibration(const optics::CameraModel& camera);

}  // namespace plenopiv::calib
