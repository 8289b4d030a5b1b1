// Fuzz target: the camera file (core/optics/camera_file): accepted ones describe a camera whose
// YAML, written back, reads as the same camera.
#include <cmath>

#include "core/optics/camera_file.hpp"
#include "tests/fuzz/fuzz_support.hpp"

using namespace plenopiv;

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  try {
    const optics::CameraModel camera = optics::parse_camera_yaml(fuzzing::as_text(data, size), "camera.yaml");
    const optics::SensorSpec& s = camera.sensor();
    fuzzing::require(s.width_px > 0 && s.height_px > 0 && s.pixel_pitch_mm > 0 && std::isfinite(s.pixel_pitch_mm),
                     "an accepted camera has an impossible sensor");
    (void)camera.summary();
    const optics::CameraModel again = optics::parse_camera_yaml(optics::to_yaml(camera.spec()), "written back");
    fuzzing::require(again.sensor().width_px == s.width_px && again.sensor().height_px == s.height_px,
                     "a camera written back reads as another camera");
  } catch (const InputError& e) {
    fuzzing::require_names(e, "camera.yaml");
  }
  return 0;
}
