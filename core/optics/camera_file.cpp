// Reads the camera description (YAML keys sensor, microlens, main_lens) into a CameraModel.
#include "core/optics/camera_file.hpp"

#include <array>
#include <limits>
#include <sstream>

#include "core/base/errors.hpp"
#include "core/base/yaml_access.hpp"

namespace plenopiv::optics {
namespace {

int count(const YamlMap& map, std::string_view key) {
  const long long v = map.integer(key);
  if (v <= 0 || v > std::numeric_limits<int>::max()) {
    map.fail(key, "must be a positive whole number, got " + std::to_string(v));
  }
  return static_cast<int>(v);
}

// [column, row] in pixels.
std::array<double, 2> pixel_position(const YamlMap& map, std::string_view key) {
  const YAML::Node& node = map.node()[std::string(key)];
  if (!node.IsSequence() || node.size() != 2) map.fail(key, "expected [column, row] in pixels");
  std::array<double, 2> p{};
  for (std::size_t k = 0; k < 2; ++k) {
    try {
      p[k] = node[k].as<double>();
    } catch (const YAML::Exception&) {
      map.fail(key, "expected [column, row] in pixels, got '" + node[k].as<std::string>("?") + "'");
    }
  }
  return p;
}

CameraModel from_root(const YAML::Node& root, const std::string& source) {
  const YamlMap top(root, source);
  top.reject_unknown({"sensor", "microlens", "main_lens"});
  CameraSpec spec;

  const YamlMap sensor = top.map("sensor");
  sensor.reject_unknown({"width_px", "height_px", "pixel_pitch_mm", "optical_axis_px"});
  spec.sensor.width_px = count(sensor, "width_px");
  spec.sensor.height_px = count(sensor, "height_px");
  spec.sensor.pixel_pitch_mm = sensor.number("pixel_pitch_mm");
  if (sensor.has("optical_axis_px")) spec.sensor.optical_axis_px = pixel_position(sensor, "optical_axis_px");

  const YamlMap lens = top.map("microlens");
  lens.reject_unknown({"pitch_mm", "focal_length_mm", "count_x", "count_y", "layout"});
  spec.microlens.pitch_mm = lens.number("pitch_mm");
  spec.microlens.focal_length_mm = lens.number("focal_length_mm");
  // Optional: an array that overfills the sensor, or one whose count nobody knows, is described
  // by its pitch and layout; calibration finds the lenses the sensor sees.
  if (lens.has("count_x")) spec.microlens.count_x = count(lens, "count_x");
  if (lens.has("count_y")) spec.microlens.count_y = count(lens, "count_y");
  spec.microlens.layout =
      lens.choice_or("layout", {"rect", "hex"}, "rect") == "hex" ? LensletLayout::hex : LensletLayout::rect;

  const YamlMap main = top.map("main_lens");
  main.reject_unknown({"focal_length_mm", "f_number", "magnification"});
  spec.main_lens.focal_length_mm = main.number("focal_length_mm");
  spec.main_lens.f_number = main.number("f_number");
  spec.main_lens.magnification = main.number("magnification");

  return CameraModel(spec, source);
}

}  // namespace

CameraModel load_camera_file(const std::filesystem::path& path) {
  return from_root(load_yaml_file(path), path.string());
}

CameraModel parse_camera_yaml(const std::string& text, const std::string& source) {
  return from_root(load_yaml_text(text, source), source);
}

std::string to_yaml(const CameraSpec& spec) {
  std::ostringstream out;
  out.precision(17);
  out << "sensor: {width_px: " << spec.sensor.width_px << ", height_px: " << spec.sensor.height_px
      << ", pixel_pitch_mm: " << spec.sensor.pixel_pitch_mm;
  if (spec.sensor.optical_axis_px) {
    out << ", optical_axis_px: [" << (*spec.sensor.optical_axis_px)[0] << ", " << (*spec.sensor.optical_axis_px)[1]
        << "]";
  }
  out << "}\n"
      << "microlens: {pitch_mm: " << spec.microlens.pitch_mm << ", focal_length_mm: " << spec.microlens.focal_length_mm;
  if (spec.microlens.count_x > 0) out << ", count_x: " << spec.microlens.count_x;
  if (spec.microlens.count_y > 0) out << ", count_y: " << spec.microlens.count_y;
  out << ", layout: " << to_string(spec.microlens.layout) << "}\n"
      << "main_lens: {focal_length_mm: " << spec.main_lens.focal_length_mm << ", f_number: " << spec.main_lens.f_number
      << ", magnification: " << spec.main_lens.magnification << "}\n";
  return out.str();
}

}  // namespace plenopiv::optics
