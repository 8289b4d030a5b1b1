// Microlens calibration (sec 3.2, fig 15): spot lattice fit, per-lens centres, white correction.
#pragma once

#include <array>
#include <cstdint>
#include <vector>

#include "core/base/image.hpp"
#include "core/calib/spots.hpp"
#include "core/optics/camera_model.hpp"
#include "core/optics/microlens_array.hpp"

namespace plenopiv::calib {

// What became of each lens in the fit.
enum class LensStatus : std::uint8_t {
  missing = 0,   // no spot found: centre taken from the lattice
  measured = 1,  // its spot's centroid is its centre
  rejected = 2,  // a spot was found but departs too far from the lattice (hot pixel, second spot)
};

// A calibrated array. The fitted lattice is the SPOT lattice on the sensor (pitch scaled by
// 1 + f_l/s_i from the lens lattice; see core/optics/microlens_array.hpp); lenses are indexed
// j * count_x + i as in optics::MicrolensArray.
struct Calibration {
  optics::SensorSpec sensor;
  double image_distance_mm = 0;          // s_i used to convert spots to lens centres
  double microlens_focal_length_mm = 0;  // f_l
  double microlens_image_diameter_px = 0;  // the main-lens aperture's image behind each lens (camera
                                           // model; not stored in the calibration file)
  optics::Lattice spot_lattice;          // sensor-plane mm, origin at the sensor centre
  std::vector<std::array<double, 2>> spots_px;     // (column, row) of each lens's spot
  std::vector<LensStatus> status;
  std::vector<std::array<double, 2>> residuals_px;  // measured - lattice; 0 for missing lenses
  double rms_residual_px = 0;  // over measured lenses
  double max_residual_px = 0;
  int spots_found = 0;         // detector output, before assignment to lenses
  int lenses_measured = 0;
  SpotImageStats image_stats;
  ImageF white_correction;     // 1 inside each microlens image falling to 0 outside (fig 15)

  // Lens centres on the microlens plane (mm), converted from the spots with spot_to_lens_centre_mm;
  // the lattice scaled likewise.
  optics::MicrolensArray microlens_array() const;
};

struct CalibrationOptions {
  SpotOptions spots;                  // max_area_px 0: set from the nominal pitch
  double outlier_px = 0.25;           // lenses further than max(this, 3 x median residual) are rejected
  double min_found_fraction = 0.5;    // fewer spots than this fraction of the lenses is an error
  double pitch_tolerance = 0.10;      // relative departure of the fitted pitch allowed
};

// Fits the spot lattice to a calibration image (stopped-down aperture, white target) taken with
// `camera`. Throws InputError saying what was found when the image has the wrong size, too few
// spots ("found 312 spots, expected about 55777"), or spots that no lattice near the camera file's
// pitch explains. The white correction is left empty (see make_white_correction).
Calibration calibrate(const optics::CameraModel& camera, const ImageF& calibration_image,
                      const CalibrationOptions& options = {});

// Fig 15: `white` (an average of open-aperture white images, same size as the sensor) minus
// `dark_level`, divided in each microlens image by that image's central level (the mean within a
// quarter pitch of its spot), clamped below at 0. Pixels nearest no lens of the array are 0, and so
// are pixels that do not overlap their lens's image disk (diameter `microlens_image_diameter_px`
// around its spot): light there is diffraction and scatter that no ray through the aperture
// reaches, and the reconstruction's separable weights rely on the white being 0 outside the disk
// to apply the circular aperture (docs/recon.md, "White correction from a measured white image").
// `light_outside_fraction`, if given, receives the share of the white's signal so removed.
// InputError if the calibration carries no image diameter (one read from a file).
ImageF make_white_correction(const Calibration& calibration, const ImageF& white, double dark_level,
                             double* light_outside_fraction = nullptr);

// For every pixel, the index (j * count_x + i) of the lens whose spot is nearest, or -1 where the
// pixel lies beyond the array's edge (further than half a pitch outside the outermost spots).
// `spots_px` as in Calibration. Row-major like the image.
std::vector<std::int32_t> pixel_lens_map(const optics::SensorSpec& sensor, const optics::Lattice& spot_lattice,
                                         const std::vector<std::array<double, 2>>& spots_px);

}  // namespace plenopiv::calib
