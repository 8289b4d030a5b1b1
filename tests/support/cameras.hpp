// The small camera of the paper's sec 5.4 (850 x 850 px, 50 x 50 lenses) for tests, rect or hex.
#pragma once

#include <string>

#include "core/optics/camera_file.hpp"

namespace plenopiv::testing_support {

// As systemd/config/camera-small.yaml; "hex" has 49 lenses per row so the shifted rows still fit.
inline optics::CameraModel small_camera(const std::string& layout = "rect") {
  return optics::parse_camera_yaml(std::string(R"(
sensor:    {width_px: 850, height_px: 850, pixel_pitch_mm: 0.0074}
microlens: {pitch_mm: 0.125, focal_length_mm: 0.5, count_x: )") +
                                       (layout == "hex" ? "49" : "50") + ", count_y: 50, layout: " + layout + R"(}
main_lens: {focal_length_mm: 50, f_number: 2, magnification: -1}
)",
                                   "small camera (" + layout + ")");
}

}  // namespace plenopiv::testing_support
