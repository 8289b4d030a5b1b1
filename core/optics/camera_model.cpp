// The plenoptic camera: sensor, microlens array and main lens, validated, with derived geometry.
#include "core/optics/camera_model.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <sstream>

#include "core/base/errors.hpp"

namespace plenopiv::optics {
namespace {

// Relative departure from f-number matching (eq 7) that earns a note: lens f-numbers are quoted
// to two digits.
constexpr double kFNumberTolerance = 0.02;

std::string fmt(double v) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.6g", v);
  return buf;
}

}  // namespace

const char* to_string(LensletLayout layout) { return layout == LensletLayout::hex ? "hex" : "rect"; }

CameraModel::CameraModel(const CameraSpec& spec, const std::string& source) : spec_(spec) {
  auto fail = [&](const std::string& key, const std::string& reason) {
    throw InputError(source + ": " + key + ": " + reason);
  };
  auto positive = [&](const std::string& key, double v) {
    if (!(v > 0) || !std::isfinite(v)) fail(key, "must be a positive number, got " + fmt(v));
  };
  const SensorSpec& s = spec_.sensor;
  const MicrolensSpec& l = spec_.microlens;
  const MainLensSpec& m = spec_.main_lens;

  if (s.width_px <= 0) fail("sensor.width_px", "must be a positive pixel count, got " + fmt(s.width_px));
  if (s.height_px <= 0) fail("sensor.height_px", "must be a positive pixel count, got " + fmt(s.height_px));
  positive("sensor.pixel_pitch_mm", s.pixel_pitch_mm);
  positive("microlens.pitch_mm", l.pitch_mm);
  positive("microlens.focal_length_mm", l.focal_length_mm);
  if (l.count_x < 0) fail("microlens.count_x", "must be a positive lens count, got " + fmt(l.count_x));
  if (l.count_y < 0) fail("microlens.count_y", "must be a positive lens count, got " + fmt(l.count_y));
  if ((l.count_x > 0) != (l.count_y > 0)) {
    fail(l.count_x > 0 ? "microlens.count_y" : "microlens.count_x",
         "give both counts or neither (without them the array is taken to cover the sensor)");
  }
  positive("main_lens.focal_length_mm", m.focal_length_mm);
  positive("main_lens.f_number", m.f_number);
  if (!std::isfinite(m.magnification) || m.magnification == 0) {
    fail("main_lens.magnification", "must be non-zero (M = -s_i/s_o; -1 for 1:1 imaging), got " + fmt(m.magnification));
  }
  if (m.magnification > 0) {
    fail("main_lens.magnification",
         "must be negative: a single main lens forms a real, inverted image (M = -s_i/s_o, eq 6), got " +
             fmt(m.magnification));
  }
  if (s.optical_axis_px) {
    const auto& a = *s.optical_axis_px;
    if (!std::isfinite(a[0]) || !std::isfinite(a[1]) || a[0] < -0.5 || a[1] < -0.5 || a[0] > s.width_px - 0.5 ||
        a[1] > s.height_px - 0.5) {
      fail("sensor.optical_axis_px",
           "[" + fmt(a[0]) + ", " + fmt(a[1]) + "] is not on the sensor: give [column, row] in pixels, 0 to " +
               fmt(s.width_px - 1) + " and 0 to " + fmt(s.height_px - 1) + " (the centre is [" +
               fmt(0.5 * (s.width_px - 1)) + ", " + fmt(0.5 * (s.height_px - 1)) + "])");
    }
  }

  if (l.pitch_mm < 2 * s.pixel_pitch_mm) {
    fail("microlens.pitch_mm", "a microlens must cover at least 2 pixels; pitch " + fmt(l.pitch_mm) +
                                   " mm with pixel pitch " + fmt(s.pixel_pitch_mm) + " mm");
  }
  // The nominal array: the lenses of a centred, unrotated array that the sensor holds whole.
  const bool hex = l.layout == LensletLayout::hex;
  const double tol = 1e-9;
  const int fit_x = int(std::floor(sensor_width_mm() / l.pitch_mm - (hex ? 0.5 : 0.0) + tol));
  const int fit_y = int(std::floor((sensor_height_mm() - l.pitch_mm) / row_pitch_mm() + tol)) + 1;
  if (fit_x < 1 || fit_y < 1) {
    fail("microlens.pitch_mm", "a lens of pitch " + fmt(l.pitch_mm) + " mm does not fit on the " +
                                   fmt(sensor_width_mm()) + " x " + fmt(sensor_height_mm()) + " mm sensor");
  }
  nominal_count_x_ = counts_given() ? std::min(l.count_x, fit_x) : fit_x;
  nominal_count_y_ = counts_given() ? std::min(l.count_y, fit_y) : fit_y;
  if (counts_given() && (l.count_x > fit_x || l.count_y > fit_y)) {
    notes_.push_back("the array of " + fmt(l.count_x) + " x " + fmt(l.count_y) + " lenses overfills the " +
                     fmt(sensor_width_mm()) + " x " + fmt(sensor_height_mm()) + " mm sensor: " + fmt(nominal_count_x_) +
                     " x " + fmt(nominal_count_y_) +
                     " whole lenses before calibration, which finds the lenses the sensor shows");
  }

  // Thin lens (eq 5) with M = -s_i/s_o (eq 6): s_i = f (1 - M), s_o = f (1 - 1/M).
  s_i_ = m.focal_length_mm * (1.0 - m.magnification);
  s_o_ = m.focal_length_mm * (1.0 - 1.0 / m.magnification);

  // F-number matching (eq 7): an image-side f-number below the microlenses' predicts overlapping
  // micro-images. The camera file's f-number is nominal (lenses are marked to a tenth of a stop,
  // and the exit pupil of a thick lens is not where the thin lens puts it), so this is a note:
  // calibration measures the fill from a white image and refuses where micro-images overlap there.
  const double image_side = image_side_f_number();
  const double lenslet = microlens_f_number();
  if (image_side < lenslet * (1 - kFNumberTolerance)) {
    notes_.push_back("main lens f/" + fmt(m.f_number) + " at M = " + fmt(m.magnification) + " gives an image-side f/" +
                     fmt(image_side) + ", faster than the f/" + fmt(lenslet) + " microlenses: micro-images of " +
                     fmt(microlens_image_diameter_px()) + " px would overlap, " + fmt(100.0 * predicted_fill()) +
                     " % of the " + fmt(spot_pitch_px()) + " px spot pitch (eq 7 matches at f/" +
                     fmt(matched_main_f_number()) +
                     "); `plenopiv calibrate` measures the fill from a white image and refuses real overlap");
  }
  if (image_side > lenslet * (1 + kFNumberTolerance)) {
    notes_.push_back("main lens f/" + fmt(m.f_number) + " is slower than the matched f/" +
                     fmt(matched_main_f_number()) + ": each microlens image fills " +
                     fmt(100.0 * lenslet / image_side) + " % of the pitch");
  }
}

double CameraModel::aperture_diameter_mm() const { return spec_.main_lens.focal_length_mm / spec_.main_lens.f_number; }
double CameraModel::image_side_f_number() const {
  return spec_.main_lens.f_number * (1.0 - spec_.main_lens.magnification);
}
double CameraModel::microlens_f_number() const { return spec_.microlens.focal_length_mm / spec_.microlens.pitch_mm; }
double CameraModel::matched_main_f_number() const {
  return microlens_f_number() / (1.0 - spec_.main_lens.magnification);
}
double CameraModel::microlens_image_diameter_px() const {
  // The cone from the aperture (diameter p_m at distance s_i) projected through a microlens
  // centre onto the sensor one focal length behind it.
  return aperture_diameter_mm() * spec_.microlens.focal_length_mm / s_i_ / spec_.sensor.pixel_pitch_mm;
}
double CameraModel::pixels_per_microlens() const { return spec_.microlens.pitch_mm / spec_.sensor.pixel_pitch_mm; }
double CameraModel::spot_pitch_px() const {
  return pixels_per_microlens() * (1.0 + spec_.microlens.focal_length_mm / s_i_);
}
double CameraModel::predicted_fill() const { return microlens_image_diameter_px() / spot_pitch_px(); }
std::array<double, 2> CameraModel::optical_axis_px() const {
  if (spec_.sensor.optical_axis_px) return *spec_.sensor.optical_axis_px;
  return {0.5 * (spec_.sensor.width_px - 1), 0.5 * (spec_.sensor.height_px - 1)};
}
CameraModel CameraModel::with_optical_axis(const std::array<double, 2>& axis_px) const {
  CameraSpec spec = spec_;
  spec.sensor.optical_axis_px = axis_px;
  return CameraModel(spec, "the optical axis measured by calibration");
}
CameraModel CameraModel::binned(int factor) const {
  const SensorSpec& s = spec_.sensor;
  if (factor < 1 || s.width_px % factor != 0 || s.height_px % factor != 0) {
    throw InputError("pixel binning " + std::to_string(factor) + " does not divide the sensor's " +
                     std::to_string(s.width_px) + " x " + std::to_string(s.height_px) + " px");
  }
  if (factor == 1) return *this;
  CameraSpec spec = spec_;
  spec.sensor.width_px = s.width_px / factor;
  spec.sensor.height_px = s.height_px / factor;
  spec.sensor.pixel_pitch_mm = s.pixel_pitch_mm * factor;
  // Binned pixel k covers raw pixels factor k .. factor k + factor - 1: its centre is raw
  // factor k + (factor - 1) / 2 (integer coordinates are pixel centres).
  if (s.optical_axis_px) {
    const auto& a = *s.optical_axis_px;
    spec.sensor.optical_axis_px =
        std::array<double, 2>{(a[0] - 0.5 * (factor - 1)) / factor, (a[1] - 0.5 * (factor - 1)) / factor};
  }
  return CameraModel(spec, "the camera binned " + std::to_string(factor) + " x " + std::to_string(factor));
}
double CameraModel::sensor_width_mm() const { return spec_.sensor.width_px * spec_.sensor.pixel_pitch_mm; }
double CameraModel::sensor_height_mm() const { return spec_.sensor.height_px * spec_.sensor.pixel_pitch_mm; }
double CameraModel::row_pitch_mm() const {
  return spec_.microlens.layout == LensletLayout::hex ? spec_.microlens.pitch_mm * std::sqrt(3.0) / 2
                                                      : spec_.microlens.pitch_mm;
}
double CameraModel::array_width_mm() const {
  const double rows_shift = spec_.microlens.layout == LensletLayout::hex && nominal_count_y_ > 1 ? 0.5 : 0.0;
  return (nominal_count_x_ + rows_shift) * spec_.microlens.pitch_mm;
}
double CameraModel::array_height_mm() const {
  // Each lens occupies one pitch across; rows are row_pitch apart.
  return (nominal_count_y_ - 1) * row_pitch_mm() + spec_.microlens.pitch_mm;
}
double CameraModel::field_of_view_x_mm() const { return array_width_mm() / std::abs(spec_.main_lens.magnification); }
double CameraModel::field_of_view_y_mm() const { return array_height_mm() / std::abs(spec_.main_lens.magnification); }
double CameraModel::nominal_voxel_size_mm() const {
  return spec_.microlens.pitch_mm / std::abs(spec_.main_lens.magnification);
}

std::string CameraModel::summary() const {
  std::ostringstream out;
  out << "sensor        " << sensor().width_px << " x " << sensor().height_px << " px, pitch "
      << fmt(sensor().pixel_pitch_mm * 1000) << " um (" << fmt(sensor_width_mm()) << " x " << fmt(sensor_height_mm())
      << " mm)\n"
      << "microlenses   " << nominal_count_x_ << " x " << nominal_count_y_ << " " << to_string(microlens().layout)
      << (counts_given()
              ? (nominal_count_x_ == microlens().count_x && nominal_count_y_ == microlens().count_y
                     ? ""
                     : " on the sensor (array " + fmt(microlens().count_x) + " x " + fmt(microlens().count_y) + ")")
              : " fit on the sensor (counts not given)")
      << ", pitch " << fmt(microlens().pitch_mm) << " mm (" << fmt(pixels_per_microlens()) << " px; spots "
      << fmt(spot_pitch_px()) << " px apart), f/" << fmt(microlens_f_number()) << "\n"
      << "optical axis  column " << fmt(optical_axis_px()[0]) << ", row " << fmt(optical_axis_px()[1])
      << (sensor().optical_axis_px ? "" : " (the sensor centre: sensor.optical_axis_px not given)") << "\n"
      << "main lens     f = " << fmt(main_lens().focal_length_mm) << " mm, f/" << fmt(main_lens().f_number)
      << ", M = " << fmt(main_lens().magnification) << " -> s_o = " << fmt(s_o_) << " mm, s_i = " << fmt(s_i_)
      << " mm, image side f/" << fmt(image_side_f_number()) << "\n"
      << "micro-images  " << fmt(microlens_image_diameter_px()) << " px across, fill " << fmt(100 * predicted_fill())
      << " % of the spot pitch (predicted from the f-number)\n"
      << "field of view " << fmt(field_of_view_x_mm()) << " x " << fmt(field_of_view_y_mm()) << " mm, nominal voxel "
      << fmt(nominal_voxel_size_mm()) << " mm\n";
  for (const std::string& note : notes_) out << "note          " << note << "\n";
  return out.str();
}

}  // namespace plenopiv::optics
