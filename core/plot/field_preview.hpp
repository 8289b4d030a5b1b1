// PNG previews of vector fields drawn with PLplot: the one owner of preview plots.
#pragma once

#include <cstdint>
#include <filesystem>
#include <span>

#include "core/base/grid.hpp"

namespace plenopiv::plot {

// Pixel size of a preview image.
struct PreviewSize {
  int width_px = 1400;
  int height_px = 640;
};

// Writes `png` (atomically, through PLplot's pngcairo device): the x-y slice through the middle
// of the field's z range in two panels, left the vorticity ω_z (1/s), right the out-of-plane
// velocity w (m/s), each on a diverging colour map centred on zero with a colour bar labelled in
// its units, and over both the in-plane velocity (u, v) as arrows. Axes x and y in mm (y down, as
// the upright image shows them), ticks at round numbers; a reference arrow with its length in
// m/s; vectors replaced by validation (`flags` bits piv::flag_second_peak, flag_third_peak,
// flag_interpolated) drawn in their own colour; nodes without a vector grey.
// `flags` holds the piv::VectorFlag bits per node, or is empty (no vector marked as replaced).
// Safe to call from several threads: PLplot's state is global, so drawings take turns.
// InputError: dt_s not > 0, flags or arrays not matching the grid, the folder of `png` missing,
// PLplot without its pngcairo device (Debian package plplot-driver-cairo).
void write_field_preview(const std::filesystem::path& png, const VectorField& field,
                         std::span<const std::uint8_t> flags, const PreviewSize& size = {});

}  // namespace plenopiv::plot
