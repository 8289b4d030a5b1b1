// A contact sheet of images (a refocused stack, perspective views) drawn with PLplot.
#include "core/plot/image_sheet.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>

#include "core/base/errors.hpp"
#include "core/plot/plplot_page.hpp"
#include "core/plot/scales.hpp"

namespace plenopiv::plot {
namespace {

// Margins around a panel, in pixels: its title above, tick labels and axis label below and left.
constexpr double kTitlePx = 30, kBelowPx = 64, kLeftPx = 70, kPaddingPx = 16;
// The page's right part, page fraction, holds the colour bar and its labels.
constexpr double kBarArea = 0.12;

void label_bar_ticks(PLINT, PLFLT value, char* label, PLINT length, PLPointer data) {
  const double step = *static_cast<const double*>(data);
  std::snprintf(label, std::size_t(length), "%s", tick_label(value, step).c_str());
}

// One image as PLplot takes it: [column][row].
std::vector<PLFLT> columns_of(const ImageF& image, std::vector<const PLFLT*>& rows) {
  std::vector<PLFLT> data(std::size_t(image.width) * image.height);
  for (int i = 0; i < image.width; ++i)
    for (int j = 0; j < image.height; ++j) data[std::size_t(i) * image.height + j] = image.at(i, j);
  rows.resize(std::size_t(image.width));
  for (int i = 0; i < image.width; ++i) rows[std::size_t(i)] = data.data() + std::size_t(i) * image.height;
  return data;
}

}  // namespace

void write_image_sheet(const std::filesystem::path& png, const std::vector<ImageF>& images,
                       const std::vector<std::string>& labels, const std::string& axis_unit, int width_px) {
  if (images.empty()) throw InputError(png.string() + ": no images for the contact sheet");
  if (labels.size() != images.size())
    throw InputError(png.string() + ": " + std::to_string(labels.size()) + " labels for " +
                     std::to_string(images.size()) + " images");
  const int w = images[0].width, h = images[0].height;
  for (const ImageF& image : images)
    if (image.width != w || image.height != h || w <= 0 || h <= 0)
      throw InputError(png.string() + ": the images of a contact sheet must be of one size");
  if (width_px < 300) throw InputError(png.string() + ": contact sheet narrower than 300 pixels");
  float top = 0;
  for (const ImageF& image : images)
    for (float v : image.pixels)
      if (std::isfinite(v)) top = std::max(top, v);
  const double limit = top > 0 ? top : 1;

  const int count = int(images.size());
  const int cols = int(std::ceil(std::sqrt(double(count))));
  const int rows = (count + cols - 1) / cols;
  const double cell_w = (1 - kBarArea) * width_px / cols;
  const double panel_w = cell_w - kLeftPx - kPaddingPx;
  const double cell_h = panel_w * h / w + kTitlePx + kBelowPx + kPaddingPx;
  const int height_px = int(std::ceil(rows * cell_h + 2 * kPaddingPx));

  draw_png_page(png, width_px, height_px, [&](plstream& pls) {
    pls.scol0(1, 0, 0, 0);
    const PLFLT at[] = {0, 1}, grey[] = {0, 1};
    pls.scmap1n(256);
    pls.scmap1l(true, 2, at, grey, grey, grey, nullptr);
    pls.schr(0, 0.7);
    const double step = nice_step(limit, 5);
    for (int k = 0; k < count; ++k) {
      const int r = k / cols, c = k % cols;
      // The cell in page fractions, y up from the bottom of the page.
      const double x0 = (c * cell_w + kLeftPx) / width_px, x1 = ((c + 1) * cell_w - kPaddingPx) / width_px;
      const double y1 = 1 - (kPaddingPx + r * cell_h + kTitlePx) / height_px;
      const double y0 = 1 - (kPaddingPx + (r + 1) * cell_h - kBelowPx) / height_px;
      pls.vpor(x0, x1, y0, y1);
      pls.wind(0, w, h, 0);
      std::vector<const PLFLT*> columns;
      const std::vector<PLFLT> data = columns_of(images[std::size_t(k)], columns);
      pls.imagefr(columns.data(), w, h, 0, w, 0, h, 0, limit, 0, limit, nullptr, nullptr);
      pls.col0(1);
      pls.box("bcnst", 0, 0, "bcnstv", 0, 0);
      pls.mtex("t", 0.8, 0.5, 0.5, labels[std::size_t(k)].c_str());
      pls.mtex("b", 2.8, 0.5, 0.5, (axis_unit + " column").c_str());
      pls.mtex("l", 3.4, 0.5, 0.5, (axis_unit + " row").c_str());
    }
    // The shared grey scale.
    pls.vpor(1 - kBarArea + 0.02, 1 - kBarArea + 0.035, 0.1, 0.9);
    pls.wind(0, 1, 0, limit);
    constexpr int levels = 256;
    std::vector<PLFLT> bar(2 * levels);
    for (int j = 0; j < levels; ++j) bar[std::size_t(j)] = bar[std::size_t(levels + j)] = limit * (j + 0.5) / levels;
    const PLFLT* bar_columns[2] = {bar.data(), bar.data() + levels};
    pls.imagefr(bar_columns, 2, levels, 0, 1, 0, limit, 0, limit, 0, limit, nullptr, nullptr);
    double bar_step = step;
    pls.slabelfunc(label_bar_ticks, &bar_step);
    pls.box("bc", 0, 0, "bcmtvo", step, 0);
    pls.slabelfunc(nullptr, nullptr);
    pls.mtex("r", 5.5, 0.5, 0.5, "intensity (counts)");
  });
}

}  // namespace plenopiv::plot
