// Fuzz target: the calibration file (core/calib/calibration_file): read whole, and loaded for a
// camera as `plenopiv process` and the daemon load it.
#include <algorithm>

#include "core/calib/calibration_file.hpp"
#include "core/optics/camera_file.hpp"
#include "tests/fuzz/seed_camera.hpp"

using namespace plenopiv;

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  static const optics::CameraModel camera = optics::parse_camera_yaml(fuzzing::kSeedCamera, "seed camera");
  const auto path = fuzzing::input_file(data, size, "calibration.h5");
  try {
    const calib::Calibration c = calib::read_calibration_h5(path);
    const std::size_t lenses = std::size_t(std::max(0, c.spot_lattice.count()));
    fuzzing::require(c.spot_lattice.count_x > 0 && c.spot_lattice.count_y > 0 && c.spots_px.size() == lenses &&
                         c.status.size() == lenses && c.residuals_px.size() == lenses,
                     "a calibration read whose per-lens arrays do not match its lattice");
    fuzzing::require(c.white_correction.size() == std::size_t(c.white_correction.width) * c.white_correction.height,
                     "a calibration read whose white correction does not match its size");
  } catch (const InputError& e) {
    fuzzing::require_names(e, path.string());
  }
  try {
    const calib::LoadedCalibration loaded = calib::load_calibration(path, camera);
    fuzzing::require(loaded.white_correction.width == camera.sensor().width_px &&
                         loaded.white_correction.height == camera.sensor().height_px,
                     "a calibration loaded for a camera with a white correction of another size");
    fuzzing::require(loaded.lenses.centres_mm.size() == std::size_t(camera.lens_count()),
                     "a calibration loaded for a camera with another lens count");
  } catch (const InputError& e) {
    fuzzing::require_names(e, path.string());
  }
  return 0;
}
