// Test support: calibration and white images rendered from known spot positions (not a simulator:
// Gaussian spots and flat discs where the lattice puts them, with the departures a real array has).
#pragma once

#include <array>
#include <cstdint>
#include <vector>

#include "core/base/image.hpp"
#include "core/optics/camera_model.hpp"
#include "core/optics/microlens_array.hpp"

namespace plenopiv::testing_support {

struct SpotScene {
  double rotation_deg = 0;
  double pitch_scale = 1;  // lens pitch relative to the camera file's
  double offset_x_mm = 0, offset_y_mm = 0;
  double jitter_mm = 0;  // each lens centre moves uniformly within +-jitter in x and y
  double spot_sigma_px = 1.0;
  double peak = 2000;     // spot amplitude at the sensor centre
  double vignetting = 0;  // amplitude falls by this fraction at the sensor corner (quadratic)
  double background = 100;
  double noise_sigma = 0;  // additive Gaussian noise
  int hot_pixels = 0;      // single pixels set to hot_value at random places
  double hot_value = 4000;
  double missing_edge_fraction = 0;  // this fraction of the outermost ring of lenses gives no spot
  std::uint32_t seed = 1;
};

struct RenderedSpots {
  ImageF image;
  optics::Lattice lens_lattice;                      // the true lens lattice (mm)
  std::vector<std::array<double, 2>> true_spots_px;  // per lens j*nx+i, (column, row)
  std::vector<std::uint8_t> lit;                     // 0 where the spot was left out
};

// Calibration image: one pixel-integrated Gaussian spot per lens at lens_centre_to_spot_mm of its
// (jittered) centre.
RenderedSpots render_calibration(const optics::CameraModel& camera, const SpotScene& scene);

// Open-aperture white image: each lens's image a disc of `disc_fraction` of the pitch in diameter
// (leaving dark gaps), brightness falling with vignetting; the same spot positions as `spots`.
ImageF render_white(const optics::CameraModel& camera, const RenderedSpots& spots, const SpotScene& scene,
                    double disc_fraction);

}  // namespace plenopiv::testing_support
