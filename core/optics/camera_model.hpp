// The plenoptic camera: sensor, microlens array and main lens, validated, with derived geometry.
#pragma once

#include <array>
#include <optional>
#include <string>
#include <vector>

namespace plenopiv::optics {

enum class LensletLayout { rect, hex };

struct SensorSpec {
  int width_px = 0;
  int height_px = 0;
  double pixel_pitch_mm = 0;
  // Where the main lens's optical axis meets the sensor: (column, row) in continuous pixel
  // coordinates (integer = pixel centre), on the sensor. The origin of sensor-plane millimetres
  // (core/optics/microlens_array.hpp). Empty: the sensor centre, ((width - 1) / 2, (height - 1) / 2).
  std::optional<std::array<double, 2>> optical_axis_px;
};

struct MicrolensSpec {
  double pitch_mm = 0;         // centre-to-centre distance of neighbours in a row
  double focal_length_mm = 0;  // sensor sits one focal length behind the array
  // Lenses per row and rows of the array as mounted; 0: not given. The array may overfill the
  // sensor; the nominal (uncalibrated) array is the part the sensor sees whole (CameraModel::
  // nominal_count_x), and calibration finds the lenses a white or calibration image shows.
  int count_x = 0;
  int count_y = 0;
  LensletLayout layout = LensletLayout::rect;  // hex: rows pitch*sqrt(3)/2 apart, odd rows shifted
};

struct MainLensSpec {
  double focal_length_mm = 0;
  double f_number = 0;       // object-side f-number set on the lens
  double magnification = 0;  // M = -s_i / s_o (eq 6); negative for a real, inverted image
};

// What a camera file says, before validation.
struct CameraSpec {
  SensorSpec sensor;
  MicrolensSpec microlens;
  MainLensSpec main_lens;
};

// A validated camera with the geometry the rest of plenopiv derives from it. Construction
// throws InputError naming the key (e.g. "microlens.pitch_mm") when the spec is not a camera.
class CameraModel {
 public:
  // `source` names where the spec came from (a file name) in error messages.
  explicit CameraModel(const CameraSpec& spec, const std::string& source = "camera");

  const CameraSpec& spec() const { return spec_; }
  const SensorSpec& sensor() const { return spec_.sensor; }
  const MicrolensSpec& microlens() const { return spec_.microlens; }
  const MainLensSpec& main_lens() const { return spec_.main_lens; }

  // Thin lens (eqs 5-6): main lens to microlens plane, and main lens to nominal focal plane.
  double image_distance_mm() const { return s_i_; }
  double object_distance_mm() const { return s_o_; }
  // Main-lens aperture diameter p_m = f_m / (f/#)_m.
  double aperture_diameter_mm() const;
  // Working f-number on the image side, (f/#)_m (1 - M): the cone that reaches a microlens.
  double image_side_f_number() const;
  double microlens_f_number() const;
  // Eq 7: the main lens f-number that exactly fills each microlens image.
  double matched_main_f_number() const;
  // Diameter of one microlens image on the sensor, in pixels (equals the pitch when matched).
  double microlens_image_diameter_px() const;

  double pixels_per_microlens() const;  // pitch / pixel pitch (16.89 for the paper's camera)
  // Distance of neighbouring micro-image centres on the sensor, pixels: the lens pitch scaled by
  // 1 + f_l / s_i (the chief rays spread from the aperture centre; lens_centre_to_spot_mm).
  double spot_pitch_px() const;
  // Micro-image diameter over the spot pitch: 1 when neighbouring micro-images touch, above 1 when
  // the camera file's f-number makes them overlap. Calibration measures the real one.
  double predicted_fill() const;
  double sensor_width_mm() const;
  double sensor_height_mm() const;
  double array_width_mm() const;  // extent of the nominal lens array on the sensor
  double array_height_mm() const;
  double row_pitch_mm() const;  // pitch for rect, pitch*sqrt(3)/2 for hex
  // Whether the camera file gives microlens.count_x and count_y.
  bool counts_given() const { return spec_.microlens.count_x > 0 && spec_.microlens.count_y > 0; }
  // The nominal array: the camera file's counts where they fit on the sensor, else (counts not
  // given, or an array that overfills the sensor) as many lenses as the sensor holds whole,
  // centred on the optical axis.
  int nominal_count_x() const { return nominal_count_x_; }
  int nominal_count_y() const { return nominal_count_y_; }
  int lens_count() const { return nominal_count_x_ * nominal_count_y_; }
  // The optical axis on the sensor, (column, row) pixels: the camera file's, else the centre.
  std::array<double, 2> optical_axis_px() const;
  // This camera with its optical axis at `axis_px` (column, row), e.g. where calibration measured
  // it; InputError when it is not on the sensor.
  CameraModel with_optical_axis(const std::array<double, 2>& axis_px) const;
  // This camera read out in blocks of `factor` x `factor` pixels (binned): pixels `factor` times
  // as large, the sensor's pixel counts divided by `factor`, the optics, the sensor's extent in mm
  // and the optical axis where they were (bin_pixels makes its frames). `factor` 1 is the camera
  // itself; InputError when `factor` is below 1 or does not divide both pixel counts.
  CameraModel binned(int factor) const;

  // Object-space field of view covered by the lens array at the nominal focal plane.
  double field_of_view_x_mm() const;
  double field_of_view_y_mm() const;
  // One microlens seen in object space: the natural voxel edge (sec 5.1).
  double nominal_voxel_size_mm() const;

  // Where the design differs from an ideal match without being wrong (e.g. a main lens stopped
  // down below f-number matching leaves dark rings between microlens images; a main lens faster
  // than matching predicts overlapping micro-images, which only a white image can confirm; an
  // array that overfills the sensor).
  const std::vector<std::string>& notes() const { return notes_; }

  // A multi-line human summary with units.
  std::string summary() const;

 private:
  CameraSpec spec_;
  double s_i_ = 0;
  double s_o_ = 0;
  int nominal_count_x_ = 0;
  int nominal_count_y_ = 0;
  std::vector<std::string> notes_;
};

const char* to_string(LensletLayout layout);

}  // namespace plenopiv::optics
