// Test support: simulated white images of arrays as mounted, and their centre errors.
#include "tests/calib/white_cases.hpp"

#include <cmath>
#include <numbers>
#include <random>
#include <sstream>

#include "core/optics/camera_file.hpp"
#include "core/sim/render.hpp"

namespace plenopiv::testing_support {
namespace {

std::string camera_yaml(const WhiteCase& c, bool with_axis, double pitch_scale) {
  const double k = c.microlens_focal_mm / c.image_distance_mm;
  const double true_pitch_mm = c.spot_pitch_px * c.pixel_pitch_mm / (1 + k);
  const double pitch_mm = true_pitch_mm * pitch_scale;
  const double matched = c.microlens_focal_mm / true_pitch_mm / 2;  // eq 7 at M = -1
  std::ostringstream y;
  y.precision(17);
  y << "sensor: {width_px: " << c.width << ", height_px: " << c.height << ", pixel_pitch_mm: " << c.pixel_pitch_mm;
  if (with_axis) {
    y << ", optical_axis_px: [" << 0.5 * (c.width - 1) + c.axis_offset_px[0] << ", "
      << 0.5 * (c.height - 1) + c.axis_offset_px[1] << "]";
  }
  y << "}\nmicrolens: {pitch_mm: " << pitch_mm << ", focal_length_mm: " << c.microlens_focal_mm
    << ", layout: " << c.layout;
  if (c.counts_in_camera_file) {
    // What a user reads off the white: the lenses whole on the sensor.
    y << ", count_x: " << int(c.width / c.spot_pitch_px) - 1 << ", count_y: " << int(c.height / c.spot_pitch_px) - 1;
  }
  y << "}\nmain_lens: {focal_length_mm: " << 0.5 * c.image_distance_mm << ", f_number: " << matched / c.fill
    << ", magnification: -1}\n";
  return y.str();
}

}  // namespace

WhiteScene render_white_scene(const WhiteCase& c) {
  const bool axis_off = c.axis_offset_px[0] != 0 || c.axis_offset_px[1] != 0;
  const optics::CameraModel truth_camera =
      optics::parse_camera_yaml(camera_yaml(c, axis_off, 1.0), c.name + " (truth)");
  WhiteScene s{
      optics::parse_camera_yaml(camera_yaml(c, axis_off && c.axis_in_camera_file, c.camera_pitch_scale), c.name),
      truth_camera,
      {},
      {},
      {},
      {},
      {}};
  const double s_i = truth_camera.image_distance_mm(), f_l = truth_camera.microlens().focal_length_mm;
  const double pp = c.pixel_pitch_mm, scale = 1 + f_l / s_i;
  const optics::Lattice lattice = sim::overfilling_lattice(
      truth_camera, truth_camera.microlens().layout, truth_camera.microlens().pitch_mm,
      c.rotation_deg * std::numbers::pi / 180, c.array_offset_px[0] * pp / scale, c.array_offset_px[1] * pp / scale, 2);
  s.truth = sim::jittered_array(lattice, c.jitter_px * pp / scale, c.seed + 17);

  sim::SensorModel sensor;
  sensor.electrons_per_ray = c.electrons_per_ray;
  sensor.shot_noise = true;
  sensor.read_noise_electrons = 8;
  sensor.dark_offset_dn = 0.02 * ((1 << c.bit_depth) - 1);
  sensor.bit_depth = c.bit_depth;
  sensor.gain_dn_per_electron = 0.6 * ((1 << c.bit_depth) - 1) / (c.rays_per_px * c.electrons_per_ray);
  std::mt19937_64 rng(c.seed);
  std::uniform_real_distribution<double> u(0, 1);
  for (int k = 0; k < c.dust; ++k) {
    sim::DustSpot d;
    d.column = u(rng) * c.width;
    d.row = u(rng) * c.height;
    d.radius_px = 3 + 12 * u(rng);
    d.edge_px = 2 + 2 * u(rng);
    d.opacity = 0.2 + 0.4 * u(rng);
    sensor.dust.push_back(d);
  }
  sim::TargetOptions target = sim::white_target();
  target.rays_per_lens =
      std::size_t(c.rays_per_px * lattice.pitch_x_mm * lattice.pitch_y_mm * scale * scale / (pp * pp));
  target.sensor = sensor;
  if (c.vignetting_stop_mm > 0) target.vignetting = {0.5 * s_i, c.vignetting_stop_mm};
  const sim::RenderResult white = sim::render_target(truth_camera, s.truth, target, c.seed);
  s.white = ImageF(c.width, c.height);
  for (std::size_t k = 0; k < white.image.size(); ++k) s.white.pixels[k] = white.image.pixels[k];
  const ImageU16 dark = sim::apply_sensor(ImageF(c.width, c.height, 0.0f), sensor, c.seed + 5);
  s.dark = ImageF(c.width, c.height);
  for (std::size_t k = 0; k < dark.size(); ++k) s.dark.pixels[k] = dark.pixels[k];

  const double radius = 0.5 * truth_camera.microlens_image_diameter_px() + 1;
  for (const auto& centre : s.truth.centres_mm) {
    const double col =
        optics::sensor_mm_to_column(truth_camera.sensor(), optics::lens_centre_to_spot_mm(centre[0], s_i, f_l));
    const double row =
        optics::sensor_mm_to_row(truth_camera.sensor(), optics::lens_centre_to_spot_mm(centre[1], s_i, f_l));
    s.spots_px.push_back({col, row});
    s.whole.push_back(col - radius >= -0.5 && row - radius >= -0.5 && col + radius <= c.width - 0.5 &&
                      row + radius <= c.height - 0.5);
  }
  return s;
}

ImageF render_calibration_frame(const WhiteCase& c, const WhiteScene& scene) {
  sim::TargetOptions target = sim::calibration_target();
  const double pitch_px = c.spot_pitch_px;
  target.rays_per_lens = std::size_t(20 * pitch_px * pitch_px);
  target.sensor.electrons_per_ray = 20;
  target.sensor.shot_noise = true;
  target.sensor.read_noise_electrons = 8;
  target.sensor.dark_offset_dn = 0.02 * 4095;
  target.sensor.bit_depth = 12;
  const sim::RenderResult r = sim::render_target(scene.truth_camera, scene.truth, target, c.seed + 99);
  ImageF out(r.image.width, r.image.height);
  for (std::size_t k = 0; k < r.image.size(); ++k) out.pixels[k] = r.image.pixels[k];
  return out;
}

CentreErrors centre_errors(const WhiteScene& scene, const calib::Calibration& cal) {
  CentreErrors e;
  double sum = 0;
  // Calibrated spots binned by pixel cell for the nearest search.
  const double cell = 0.5 * cal.spot_lattice.pitch_x_mm / cal.sensor.pixel_pitch_mm;
  const int gx = int(scene.white.width / cell) + 1, gy = int(scene.white.height / cell) + 1;
  std::vector<std::vector<int>> bins(std::size_t(gx) * gy);
  for (std::size_t k = 0; k < cal.spots_px.size(); ++k) {
    const auto& q = cal.spots_px[k];
    const int bx = int(std::floor(q[0] / cell)), by = int(std::floor(q[1] / cell));
    if (bx >= 0 && by >= 0 && bx < gx && by < gy) bins[std::size_t(by) * gx + bx].push_back(int(k));
  }
  for (std::size_t t = 0; t < scene.spots_px.size(); ++t) {
    if (!scene.whole[t]) continue;
    ++e.whole;
    const auto& p = scene.spots_px[t];
    double best = 1e9;
    int who = -1;
    const int bx = int(std::floor(p[0] / cell)), by = int(std::floor(p[1] / cell));
    for (int y = std::max(0, by - 1); y <= std::min(gy - 1, by + 1); ++y) {
      for (int x = std::max(0, bx - 1); x <= std::min(gx - 1, bx + 1); ++x) {
        for (int k : bins[std::size_t(y) * gx + x]) {
          const double d = std::hypot(cal.spots_px[std::size_t(k)][0] - p[0], cal.spots_px[std::size_t(k)][1] - p[1]);
          if (d < best) {
            best = d;
            who = k;
          }
        }
      }
    }
    if (who < 0 || best > 0.5 || cal.status[std::size_t(who)] == calib::LensStatus::missing) continue;
    ++e.found;
    sum += best * best;
    e.max_px = std::max(e.max_px, best);
  }
  e.rms_px = e.found > 0 ? std::sqrt(sum / e.found) : 0.0;
  return e;
}

}  // namespace plenopiv::testing_support
