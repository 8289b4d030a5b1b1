// One PNG page drawn with PLplot's pngcairo device: the only place core/plot starts PLplot.
#pragma once

#include <plstream.h>

#include <filesystem>
#include <functional>

namespace plenopiv::plot {

// Draws one page of `width_px` x `height_px` on white paper with `draw` and writes it to `png`
// atomically. PLplot's state is global and not thread-safe: pages are drawn one at a time, by
// whichever thread calls. InputError: the folder of `png` missing, or PLplot without its pngcairo
// device (Debian package plplot-driver-cairo); std::runtime_error when PLplot wrote no image.
void draw_png_page(const std::filesystem::path& png, int width_px, int height_px,
                   const std::function<void(plstream&)>& draw);

}  // namespace plenopiv::plot
