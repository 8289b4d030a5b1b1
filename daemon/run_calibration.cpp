// The calibration a run processes with: the rig's calibration file, read and checked at run start,
// handed to the processing stage and copied byte for byte into the run folder.
#include "daemon/run_calibration.hpp"

#include "core/base/errors.hpp"
#include "core/io/checksum.hpp"

namespace plenopiv::daemon {

std::string RunCalibration::summary() const {
  if (nominal()) return "nominal lattice and geometric white image (no calibration_file)";
  return source.string() + " (" + std::to_string(bytes.size()) + " bytes, crc32 " + io::crc32_hex(crc32) + ", " +
         std::to_string(loaded ? loaded->lenses.centres_mm.size() : 0) + " lenses)";
}

RunCalibration load_run_calibration(const std::filesystem::path& file, const optics::CameraModel& camera) {
  RunCalibration c;
  if (file.empty()) return c;
  try {
    c.source = file;
    c.bytes = io::read_file_bytes(file);
    c.crc32 = io::crc32_of(c.bytes);
    c.loaded = calib::load_calibration(file, camera);
    const std::string again = io::read_file_bytes(file);
    if (again != c.bytes) throw InputError(file.string() + ": changed while it was being read; try again");
  } catch (const InputError& e) {
    throw InputError(std::string("calibration_file: ") + e.what());
  }
  return c;
}

}  // namespace plenopiv::daemon
