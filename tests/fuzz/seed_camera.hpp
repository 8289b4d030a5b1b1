// Fuzz targets: the small camera their seed files were made for (tests/fuzz/make_seeds.sh writes
// it as corpus/camera.yaml): 85 x 85 pixels behind 5 x 5 microlenses, the optics of
// systemd/config/camera-small.yaml, so that a seed calibration or frame loads and renders quickly.
#pragma once

#include <filesystem>
#include <fstream>

#include "tests/fuzz/fuzz_support.hpp"

namespace plenopiv::fuzzing {

inline constexpr const char* kSeedCamera =
    "sensor:    {width_px: 85, height_px: 85, pixel_pitch_mm: 0.0074}\n"
    "microlens: {pitch_mm: 0.125, focal_length_mm: 0.5, count_x: 5, count_y: 5, layout: rect}\n"
    "main_lens: {focal_length_mm: 50, f_number: 2, magnification: -1}\n";

// The seed camera as a file in the scratch folder.
inline const std::filesystem::path& seed_camera_file() {
  static const std::filesystem::path path = [] {
    const auto p = scratch_dir() / "camera.yaml";
    std::ofstream(p) << kSeedCamera;
    return p;
  }();
  return path;
}

}  // namespace plenopiv::fuzzing
