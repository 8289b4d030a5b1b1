// Calibration from raw frame files, the one way `plenopiv calibrate` and `plenopiv process --white`
// build it.
#pragma once

#include <string>
#include <vector>

#include "core/calib/calibration.hpp"
#include "core/optics/camera_model.hpp"

namespace plenopiv::client {

// The frames of each kind (PNG or TIFF, see io::read_raw_frame); each kind is averaged.
struct CalibrationFrameFiles {
  std::vector<std::string> white;        // required
  std::vector<std::string> calibration;  // optional: stopped down; the centres come from it when given
  std::vector<std::string> dark;         // optional: subtracted from the others
};

// Reads the frames, says on stderr what it reads and which image the centres come from, and runs
// calib::calibrate_camera. An InputError names the file(s) its message is about.
// `light_outside_fraction`: as calib::calibrate_camera.
calib::Calibration calibrate_from_files(const optics::CameraModel& camera, const CalibrationFrameFiles& files,
                                        double* light_outside_fraction = nullptr);

}  // namespace plenopiv::client
