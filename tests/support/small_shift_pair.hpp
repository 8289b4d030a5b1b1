// Tests: the small camera's shifted pair for comparing calibrations end to end (settings and frames).
#pragma once

#include <array>
#include <string>
#include <vector>

#include "core/base/image.hpp"
#include "core/base/yaml_access.hpp"
#include "core/optics/camera_model.hpp"
#include "core/process/process.hpp"
#include "core/sim/particles.hpp"
#include "core/sim/render.hpp"

namespace plenopiv::testing_support {

// process.yaml's MART on a 4 x 4 x 4 mm box behind the focal plane (0.125 mm cubes, a 1 mm depth
// guard), the median test lenient enough that a calibration's small errors are not filtered away.
inline process::ProcessSettings small_shift_settings(const std::string& source) {
  return process::process_settings_from(YamlMap(load_yaml_text(R"(
dt_s: 0.0001
volume: {x_mm: [-2, 2], y_mm: [-2, 2], z_mm: [0, 4], voxel_mm: 0.125, voxel_z_mm: 0.125, depth_guard_mm: 1}
reconstruction: {iterations: 20, mu: 1, start: mlos, noise_threshold: 0, dark_weight_cutoff: 0.9}
correlation: {median: {threshold: 2, epsilon_voxel: 0.1, radius: 2}, signal_threshold: 0}
)",
                                                               source),
                                                source));
}

struct FramePair {
  ImageF a, b;
};

// 400 particles in a box 0.5 mm beyond small_shift_settings' volume, moved by `shift_mm`, rendered
// through `lenses` with 10000 rays each (no sensor noise); the same frames on every call.
inline FramePair small_shift_pair(const optics::CameraModel& camera, const optics::MicrolensArray& lenses,
                                  const std::array<double, 3>& shift_mm) {
  const std::vector<sim::Point3> a = sim::random_particles({{-2.5, -2.5, -0.5}, {2.5, 2.5, 4.5}}, 400, 7);
  std::vector<sim::Point3> b = a;
  for (auto& p : b) p = {p[0] + shift_mm[0], p[1] + shift_mm[1], p[2] + shift_mm[2]};
  sim::RenderOptions ro;
  ro.rays_per_particle = 10000;
  return {sim::render(camera, lenses, a, ro, 3).rays, sim::render(camera, lenses, b, ro, 4).rays};
}

}  // namespace plenopiv::testing_support
