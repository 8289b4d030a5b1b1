// The calibration a run processes with: the rig's calibration file, read and checked at run start,
// handed to the processing stage and copied byte for byte into the run folder.
#pragma once

#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>

#include "core/calib/calibration_file.hpp"
#include "core/optics/camera_model.hpp"

namespace plenopiv::daemon {

struct RunCalibration {
  std::filesystem::path source;  // plenopivd.yaml calibration_file; empty: nominal
  std::string bytes;             // the file as read: what the processing loaded, what the run folder keeps
  std::uint32_t crc32 = 0;       // of `bytes` (io::crc32_of)
  // Lens centres and white correction from the file; empty when nominal (the processing then uses
  // the camera file's nominal lattice and the geometric white image).
  std::optional<calib::LoadedCalibration> loaded;

  bool nominal() const { return source.empty(); }
  // One line for logs and status: "nominal lattice and geometric white image (no calibration_file)"
  // or "<file> (<bytes> bytes, crc32 <hex>, <n> lenses)".
  std::string summary() const;
};

// Empty `file`: nominal. Otherwise reads `file` once and checks it against `camera`
// (calib::load_calibration: sensor size, lens count and layout, s_i and f_l). A missing,
// unreadable or corrupt file, one that is not a calibration file, or one made for another camera
// is an InputError "calibration_file: <file>: <why>". The bytes are read before and after the
// check and must agree (a file replaced meanwhile is an InputError too), so `bytes` is exactly
// what was loaded.
RunCalibration load_run_calibration(const std::filesystem::path& file, const optics::CameraModel& camera);

}  // namespace plenopiv::daemon
