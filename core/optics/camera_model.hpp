// The plenoptic camera: sensor, microlens array and main lens, validated, with derived geometry.
#pragma once

#include <string>
#include <vector>

namespace plenopiv::optics {

enum class LensletLayout { rect, hex };

struct SensorSpec {
  int width_px = 0;
  int height_px = 0;
  double pixel_pitch_mm = 0;
};

struct MicrolensSpec {
  double pitch_mm = 0;         // centre-to-centre distance of neighbours in a row
  double focal_length_mm = 0;  // sensor sits one focal length behind the array
  int count_x = 0;             // lenses per row
  int count_y = 0;             // rows
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
  double sensor_width_mm() const;
  double sensor_height_mm() const;
  double array_width_mm() const;   // extent of the lens array on the sensor
  double array_height_mm() const;
  double row_pitch_mm() const;     // pitch for rect, pitch*sqrt(3)/2 for hex
  int lens_count() const { return spec_.microlens.count_x * spec_.microlens.count_y; }

  // Object-space field of view covered by the lens array at the nominal focal plane.
  double field_of_view_x_mm() const;
  double field_of_view_y_mm() const;
  // One microlens seen in object space: the natural voxel edge (sec 5.1).
  double nominal_voxel_size_mm() const;

  // Where the design differs from an ideal match without being wrong (e.g. a main lens stopped
  // down below f-number matching leaves dark rings between microlens images).
  const std::vector<std::string>& notes() const { return notes_; }

  // A multi-line human summary with units.
  std::string summary() const;

 private:
  CameraSpec spec_;
  double s_i_ = 0;
  double s_o_ = 0;
  std::vector<std::string> notes_;
};

const char* to_string(LensletLayout layout);

}  // namespace plenopiv::optics
