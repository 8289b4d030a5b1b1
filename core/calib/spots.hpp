// Calibration spots: one sub-pixel centroid per bright spot of a stopped-down calibration image.
#pragma once

#include <vector>

#include "core/base/image.hpp"

namespace plenopiv::calib {

// One detected spot: intensity-weighted centroid in continuous pixel coordinates (integer values
// are pixel centres, as core/optics/microlens_array.hpp), its summed signal and its pixel count.
struct Spot {
  double column = 0;
  double row = 0;
  double signal = 0;
  int area = 0;
};

// What the detector measured about the image, reported to the user and kept in the file.
struct SpotImageStats {
  double background = 0;    // median of the image: the dark level between spots
  double noise_sigma = 0;   // 1.4826 * median absolute deviation
  double threshold = 0;     // detection level (absolute)
  int hot_pixels = 0;       // isolated bright pixels replaced by their neighbours' median
  int rejected_large = 0;   // components larger than max_area_px (merged or saturated blobs)
  int rejected_border = 0;  // components touching the image border (centroid would be biased)
};

struct SpotOptions {
  double threshold_sigma = 6.0;      // detection level above background, in noise sigmas ...
  double threshold_fraction = 0.05;  // ... but at least this fraction of the bright-spot level
  double hot_pixel_ratio = 3.0;      // a pixel this many times brighter than every neighbour is hot
  double max_area_px = 0;            // larger components are refused (0: no limit)
};

// Finds every spot. The image must hold finite, non-negative values (InputError otherwise).
// Hot pixels are removed before detection; each spot's centroid is taken over its bounding box
// grown by one pixel, weights = max(value - background, 0), pixels of other spots excluded.
// Spots come out in raster order of their first pixel; the result does not depend on threads.
std::vector<Spot> find_spots(const ImageF& image, const SpotOptions& options, SpotImageStats* stats = nullptr);

}  // namespace plenopiv::calib
