// Where the microlenses are: the lattice (pitch, rotation, offset, rect|hex) and per-lens centres,
// and the plane-to-plane geometry every module shares (sensor pixels, microlens plane, aperture).
#pragma once

#include <array>
#include <vector>

#include "core/optics/camera_model.hpp"

namespace plenopiv::optics {

// A regular lattice of microlenses on the microlens plane, in sensor-plane millimetres (x right
// along columns, y down along rows, origin at the sensor centre; see pixel_to_sensor_mm).
// Lens (i, j), i along a row, j the row: local position
//   rect: a = (i - (nx-1)/2) px,                     b = (j - (ny-1)/2) py
//   hex:  a = (i - (nx-1)/2 + (j odd ? 0.25 : -0.25)) px,  b = (j - (ny-1)/2) py
// then rotated by `rotation_rad` (counter-clockwise as seen on the upright image: +x towards -y)
// and shifted by the offset. py is the row spacing (pitch * sqrt(3)/2 for hex).
struct Lattice {
  LensletLayout layout = LensletLayout::rect;
  int count_x = 0;
  int count_y = 0;
  double pitch_x_mm = 0;
  double pitch_y_mm = 0;
  double rotation_rad = 0;
  double offset_x_mm = 0;
  double offset_y_mm = 0;

  // The nominal lattice of a camera: its nominal counts (CameraModel::nominal_count_x), centred on
  // the optical axis, not rotated.
  static Lattice nominal(const CameraModel& camera);
  // Lattice position of lens (i, j), mm.
  std::array<double, 2> position(int i, int j) const;
  int count() const { return count_x * count_y; }
};

// The lenses of one array: the lattice plus each lens's own centre (index j * count_x + i),
// which departs from the lattice where the array is imperfect or calibration measured it so.
struct MicrolensArray {
  Lattice lattice;
  std::vector<std::array<double, 2>> centres_mm;  // on the microlens plane

  // Centres exactly on the lattice.
  static MicrolensArray from_lattice(const Lattice& lattice);
  const std::array<double, 2>& centre(int i, int j) const { return centres_mm[std::size_t(j) * lattice.count_x + i]; }
};

// Sensor coordinates (DESIGN.md): x_s = (column + 0.5 - width/2) * pitch, y_s likewise with rows,
// i.e. millimetres from the sensor centre; when the camera file gives sensor.optical_axis_px,
// millimetres from that point instead (x_s = (column - axis column) * pitch): the optical axis is
// the origin of the sensor plane, as of object space. `column` and `row` may be fractional:
// integer values are pixel centres, so pixel k covers [k - 0.5, k + 0.5) in these coordinates.
inline double column_to_sensor_mm(const SensorSpec& s, double column) {
  if (s.optical_axis_px) return (column - (*s.optical_axis_px)[0]) * s.pixel_pitch_mm;
  return (column + 0.5 - 0.5 * s.width_px) * s.pixel_pitch_mm;
}
inline double row_to_sensor_mm(const SensorSpec& s, double row) {
  if (s.optical_axis_px) return (row - (*s.optical_axis_px)[1]) * s.pixel_pitch_mm;
  return (row + 0.5 - 0.5 * s.height_px) * s.pixel_pitch_mm;
}
inline double sensor_mm_to_column(const SensorSpec& s, double x_mm) {
  if (s.optical_axis_px) return x_mm / s.pixel_pitch_mm + (*s.optical_axis_px)[0];
  return x_mm / s.pixel_pitch_mm + 0.5 * s.width_px - 0.5;
}
inline double sensor_mm_to_row(const SensorSpec& s, double y_mm) {
  if (s.optical_axis_px) return y_mm / s.pixel_pitch_mm + (*s.optical_axis_px)[1];
  return y_mm / s.pixel_pitch_mm + 0.5 * s.height_px - 0.5;
}

// The chief ray from the aperture centre through a microlens centre x_l lands one microlens focal
// length behind it at x_l (1 + f_l / s_i): the centre of that lens's image (its calibration spot).
inline double lens_centre_to_spot_mm(double lens_mm, double s_i, double f_l) { return lens_mm * (1.0 + f_l / s_i); }
inline double spot_to_lens_centre_mm(double spot_mm, double s_i, double f_l) { return spot_mm / (1.0 + f_l / s_i); }
// Eq 1 with its sign: a ray from aperture point u through the microlens at x_l arrives (the lens
// focuses parallel rays) at x_s = x_spot - u f_l / s_i, so u = (x_spot - x_s) s_i / f_l. A pixel
// right of its spot sees the left of the aperture.
inline double aperture_from_sensor_mm(double sensor_mm, double spot_mm, double s_i, double f_l) {
  return (spot_mm - sensor_mm) * s_i / f_l;
}

}  // namespace plenopiv::optics
