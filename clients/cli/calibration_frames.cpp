// Calibration from raw frame files, the one way `plenopiv calibrate` and `plenopiv process --white`
// build it.
#include "clients/cli/calibration_frames.hpp"

#include <iostream>

#include "core/base/errors.hpp"
#include "core/io/raw_frame.hpp"

namespace plenopiv::client {
namespace {

// "a.png" or "a.png (+2 more)": the files an error is about.
std::string named(const std::vector<std::string>& paths) {
  return paths.front() + (paths.size() > 1 ? " (+" + std::to_string(paths.size() - 1) + " more)" : "");
}

}  // namespace

calib::Calibration calibrate_from_files(const optics::CameraModel& camera, const CalibrationFrameFiles& files,
                                        double* light_outside_fraction) {
  if (files.white.empty()) throw InputError("calibration from frames needs at least one --white frame");
  std::cerr << "reading " << files.white.size() << " white, " << files.calibration.size() << " calibration and "
            << files.dark.size() << " dark frame(s)\n";
  calib::CalibrationFrames frames;
  frames.white = io::read_mean_frame(files.white, "white");
  frames.white_frames = int(files.white.size());
  if (!files.calibration.empty()) {
    frames.calibration = io::read_mean_frame(files.calibration, "calibration");
    frames.calibration_frames = int(files.calibration.size());
  }
  if (!files.dark.empty()) {
    frames.dark = io::read_mean_frame(files.dark, "dark");
    frames.dark_frames = int(files.dark.size());
  }
  std::cerr << "calibrating from the " << (frames.calibration.empty() ? "white" : "calibration") << " image\n";
  try {
    return calib::calibrate_camera(camera, frames, {}, light_outside_fraction);
  } catch (const InputError& e) {
    // The message says which image (calibration, white or dark) it is about; name its files.
    const std::string what = e.what();
    const auto& culprit = what.rfind("white", 0) == 0  ? files.white
                          : what.rfind("dark", 0) == 0 ? (files.dark.empty() ? files.white : files.dark)
                          : files.calibration.empty()  ? files.white
                                                       : files.calibration;
    throw InputError(named(culprit) + ": " + what);
  }
}

}  // namespace plenopiv::client
