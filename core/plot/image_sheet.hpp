// A contact sheet of images (a refocused stack, perspective views) drawn with PLplot.
#pragma once

#include <filesystem>
#include <string>
#include <vector>

#include "core/base/image.hpp"

namespace plenopiv::plot {

// Writes `png` (atomically): the images in a grid of panels, `width_px` wide, each titled with its
// label, on one grey scale shared by all (black 0, white the brightest pixel of the stack, so
// relative sharpness shows) with a colour bar "intensity (counts)"; axes in image columns and rows
// (`axis_unit`, e.g. "lens": one pixel per microlens), row 0 at the top. Images of one size, one
// label each. InputError: no images, sizes or label count not matching, the folder missing.
void write_image_sheet(const std::filesystem::path& png, const std::vector<ImageF>& images,
                       const std::vector<std::string>& labels, const std::string& axis_unit, int width_px = 1200);

}  // namespace plenopiv::plot
