// Reads the camera description (YAML keys sensor, microlens, main_lens) into a CameraModel.
#pragma once

#include <filesystem>
#include <string>

#include "core/optics/camera_model.hpp"

namespace plenopiv::optics {

// Throws InputError naming the file and the key for every malformed or invalid entry.
CameraModel load_camera_file(const std::filesystem::path& path);
CameraModel parse_camera_yaml(const std::string& text, const std::string& source);
// The same YAML as the camera file, for manifests and run folders.
std::string to_yaml(const CameraSpec& spec);

}  // namespace plenopiv::optics
