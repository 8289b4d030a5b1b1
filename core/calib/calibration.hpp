// Microlens calibration (sec 3.2, fig 15): micro-image centres from a calibration (stopped-down) or
// white image, lattice and distortion fit, per-lens centres by evidence, white correction.
#pragma once

#include <array>
#include <cmath>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "core/base/image.hpp"
#include "core/calib/spots.hpp"
#include "core/optics/camera_model.hpp"
#include "core/optics/microlens_array.hpp"

namespace plenopiv::calib {

// What became of each lens in the fit. Every lens has a centre; the status says where it came from.
enum class LensStatus : std::uint8_t {
  missing = 0,   // no micro-image on the sensor (beyond its edge, or unlit): the fitted lattice's position
  measured = 1,  // its own measurement (weighted towards the fitted lattice by how much it can be trusted)
  rejected = 2,  // measured, but flawed (dust, a hot pixel, a second spot, far off the lattice): lattice used
  partial = 3,   // its micro-image is cut by the sensor edge: lattice used
  lattice = 4,   // measured, but its measurement scatters more than the array departs from the
                 // lattice: the fitted lattice (with its distortion) is the better centre
};

// Which image gave the centres.
enum class CentreSource : std::uint8_t { spots = 0, white = 1 };

// A calibrated array. The fitted lattice is the SPOT lattice on the sensor (pitch scaled by
// 1 + f_l/s_i from the lens lattice; see core/optics/microlens_array.hpp); lenses are indexed
// j * count_x + i as in optics::MicrolensArray. The array is the lenses the sensor shows (at
// least the camera file's counts, when it gives them and they fit on the sensor).
struct Calibration {
  optics::SensorSpec sensor;               // the frame: sensor-plane mm from its optical axis
  double image_distance_mm = 0;            // s_i used to convert spots to lens centres
  double microlens_focal_length_mm = 0;    // f_l
  double microlens_image_diameter_px = 0;  // the camera model's micro-image diameter (not stored)
  CentreSource source = CentreSource::spots;
  optics::Lattice spot_lattice;                 // sensor-plane mm, origin at the optical axis
  std::vector<std::array<double, 2>> spots_px;  // (column, row) of each lens's centre on the sensor
  std::vector<LensStatus> status;
  std::vector<std::array<double, 2>> residuals_px;  // measured - model (lattice + distortion); 0 if none
  std::vector<std::array<double, 2>> measured_px;   // each lens's own measurement; NaN if none
  std::vector<double> uncertainty_px;               // its 1-sigma uncertainty per axis; NaN if none
  double rms_residual_px = 0;                       // measured - model over the lenses measured whole (status 1 and 4)
  double max_residual_px = 0;
  int spots_found = 0;      // micro-images (or spots) found on the lattice, whole and partial
  int lenses_measured = 0;  // status measured
  int lenses_lattice = 0;   // status lattice
  int lenses_partial = 0;
  int lenses_rejected = 0;
  int lenses_vignetted = 0;  // among status lattice: cat's-eye micro-images (white images)
  // Evidence for lattice against per-lens centres (pixels): the scatter of the measurements (RMS
  // of their uncertainties), the departures of the array from its model that the measurements
  // show beyond that scatter, and the model's smooth distortion (0: the lattice alone).
  double measurement_scatter_px = 0;
  double array_scatter_px = 0;
  int distortion_degree = 0;
  // The pitch the image shows against the camera file's (spot pitch, along rows), and what that
  // means; the lens pitch follows the measurement (Calibration::microlens_array).
  double nominal_spot_pitch_px = 0;
  double pitch_ratio = 1;  // measured / camera file
  // From the white image: micro-image diameter over the spot pitch (NaN if not measured) and the
  // camera model's prediction; the optical axis from the white's fall-off (NaN if not measurable).
  double fill = std::nan("");
  double predicted_fill = 0;
  std::array<double, 2> measured_axis_px{std::nan(""), std::nan("")};
  double measured_axis_sigma_px = std::nan("");
  // Whether `sensor`'s optical axis is the measured one: a white with cat's-eye vignetting and a
  // camera file without sensor.optical_axis_px (load_calibration then gives it to the consumers).
  bool axis_measured = false;
  // The camera file's lens counts when calibrated (0: not given).
  int camera_count_x = 0, camera_count_y = 0;
  // Frames averaged, and the black level taken off the white.
  int calibration_frames = 0, white_frames = 0, dark_frames = 0;
  double white_black_level = 0;
  SpotImageStats image_stats;  // of the image the centres came from
  ImageF white_correction;     // 1 inside each microlens image falling to 0 outside (fig 15)
  // What the user should know: disagreements with the camera file and what to try.
  std::vector<std::string> notes;

  // Lens centres on the microlens plane (mm), converted from the spots with spot_to_lens_centre_mm;
  // the lattice scaled likewise.
  optics::MicrolensArray microlens_array() const;
};

struct CalibrationOptions {
  double min_found_fraction = 0.5;  // fewer micro-images than this share of the lenses expected is an error
  double pitch_tolerance = 0.10;    // relative departure from the camera file's spot pitch allowed
  double max_fill = 1.05;           // measured micro-image diameter over pitch above which they overlap
  int max_distortion_degree = 3;    // highest polynomial degree tried for the array's distortion
};

// Fits the lattice to a calibration image (stopped-down aperture, white target: one spot per
// microlens) taken with `camera`. Throws InputError saying what was found and what to try when
// the image has the wrong size, too few spots ("found 312 spots, expected about 55 777"), or
// spots that no lattice near the camera file's pitch explains. No white correction (see
// make_white_correction) and no fill (see measure_white).
Calibration calibrate(const optics::CameraModel& camera, const ImageF& calibration_image,
                      const CalibrationOptions& options = {});

// The same from a white image alone (aperture as used, white target): each micro-image is the
// aperture's (vignetted) disk, centred on its lens's chief ray; its centre is found by fitting the
// image's own mean micro-image. Also measures the fill and the optical axis (measure_white).
Calibration calibrate_from_white(const optics::CameraModel& camera, const ImageF& white,
                                 const CalibrationOptions& options = {});

// The white image's evidence on a calibration (its centres from this white or a calibration
// image): the black level (`black_level` when known, e.g. 0 for a dark-subtracted white; else the
// level between micro-images), the micro-image fill (the diameter of a flat disk passing each
// lens's light at its centre's level, over the pitch) and the optical axis (the centre of the
// white's radial fall-off, where it has one). Adds notes where the camera file disagrees;
// InputError when the micro-images overlap (fill above max_fill).
void measure_white(Calibration& calibration, const ImageF& white, const CalibrationOptions& options = {},
                   std::optional<double> black_level = std::nullopt);

// Calibration from the frames a user has: `calibration` (averaged stopped-down frames; may be
// empty), `white` (averaged white frames, required), `dark` (averaged dark frames; may be empty:
// then the white's black level is taken from the gaps between its micro-images where it has
// them, else 0). Centres from the calibration image when given, else from the white; then
// measure_white and the white correction. The frame counts go into the result for the record.
struct CalibrationFrames {
  ImageF calibration;
  ImageF white;
  ImageF dark;
  int calibration_frames = 0, white_frames = 0, dark_frames = 0;
};
Calibration calibrate_camera(const optics::CameraModel& camera, const CalibrationFrames& frames,
                             const CalibrationOptions& options = {}, double* light_outside_fraction = nullptr);

// A few lines for the user: what was found, against the camera file, and the notes.
std::string describe(const Calibration& calibration);

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
