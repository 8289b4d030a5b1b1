// Test support: calibration and white images rendered from known spot positions.
#include "tests/calib/spot_render.hpp"

#include <algorithm>
#include <cmath>
#include <numbers>
#include <random>

namespace plenopiv::testing_support {
namespace {

double vignette(const optics::CameraModel& camera, const SpotScene& scene, double col, double row) {
  const double hx = 0.5 * camera.sensor().width_px, hy = 0.5 * camera.sensor().height_px;
  const double r2 = ((col - hx) * (col - hx) + (row - hy) * (row - hy)) / (hx * hx + hy * hy);
  return 1.0 - scene.vignetting * r2;
}

}  // namespace

RenderedSpots render_calibration(const optics::CameraModel& camera, const SpotScene& scene) {
  RenderedSpots out;
  const auto& s = camera.sensor();
  out.lens_lattice = optics::Lattice::nominal(camera);
  out.lens_lattice.pitch_x_mm *= scene.pitch_scale;
  out.lens_lattice.pitch_y_mm *= scene.pitch_scale;
  out.lens_lattice.rotation_rad = scene.rotation_deg * std::numbers::pi / 180;
  out.lens_lattice.offset_x_mm = scene.offset_x_mm;
  out.lens_lattice.offset_y_mm = scene.offset_y_mm;
  std::mt19937 rng(scene.seed);
  std::uniform_real_distribution<double> jitter(-scene.jitter_mm, scene.jitter_mm);
  std::uniform_real_distribution<double> unit(0, 1);
  const int nx = out.lens_lattice.count_x, ny = out.lens_lattice.count_y;
  const double s_i = camera.image_distance_mm(), f_l = camera.microlens().focal_length_mm;
  out.image = ImageF(s.width_px, s.height_px, float(scene.background));
  for (int j = 0; j < ny; ++j) {
    for (int i = 0; i < nx; ++i) {
      auto c = out.lens_lattice.position(i, j);
      c[0] += jitter(rng);
      c[1] += jitter(rng);
      const double col = optics::sensor_mm_to_column(s, optics::lens_centre_to_spot_mm(c[0], s_i, f_l));
      const double row = optics::sensor_mm_to_row(s, optics::lens_centre_to_spot_mm(c[1], s_i, f_l));
      out.true_spots_px.push_back({col, row});
      const bool edge = i == 0 || j == 0 || i == nx - 1 || j == ny - 1;
      const bool lit = !(edge && unit(rng) < scene.missing_edge_fraction);
      out.lit.push_back(lit);
      if (!lit) continue;
      const double amp = scene.peak * vignette(camera, scene, col, row);
      const double sg = scene.spot_sigma_px * std::sqrt(2.0);
      auto cdf = [&](double t) { return 0.5 * std::erfc(-t / sg); };
      const int r = int(std::ceil(5 * scene.spot_sigma_px));
      for (int y = int(row) - r; y <= int(row) + r + 1; ++y) {
        if (y < 0 || y >= s.height_px) continue;
        const double wy = cdf(y + 0.5 - row) - cdf(y - 0.5 - row);
        for (int x = int(col) - r; x <= int(col) + r + 1; ++x) {
          if (x < 0 || x >= s.width_px) continue;
          const double wx = cdf(x + 0.5 - col) - cdf(x - 0.5 - col);
          out.image.at(x, y) += float(amp * wx * wy * 2 * std::numbers::pi * scene.spot_sigma_px * scene.spot_sigma_px);
        }
      }
    }
  }
  std::normal_distribution<double> noise(0, scene.noise_sigma > 0 ? scene.noise_sigma : 1);
  for (float& v : out.image.pixels) {
    if (scene.noise_sigma > 0) v += float(noise(rng));
    v = std::max(v, 0.0f);
  }
  std::uniform_int_distribution<int> px(1, s.width_px - 2), py(1, s.height_px - 2);
  for (int k = 0; k < scene.hot_pixels; ++k) out.image.at(px(rng), py(rng)) = float(scene.hot_value);
  return out;
}

ImageF render_white(const optics::CameraModel& camera, const RenderedSpots& spots, const SpotScene& scene,
                    double disc_fraction) {
  const auto& s = camera.sensor();
  ImageF white(s.width_px, s.height_px, float(scene.background));
  const double pitch_px = camera.microlens().pitch_mm / s.pixel_pitch_mm;
  const double radius = 0.5 * disc_fraction * pitch_px;
  for (const auto& q : spots.true_spots_px) {
    const double level = 3000 * vignette(camera, scene, q[0], q[1]);
    for (int y = int(q[1] - radius) - 1; y <= int(q[1] + radius) + 1; ++y) {
      if (y < 0 || y >= s.height_px) continue;
      for (int x = int(q[0] - radius) - 1; x <= int(q[0] + radius) + 1; ++x) {
        if (x < 0 || x >= s.width_px) continue;
        if (std::hypot(x - q[0], y - q[1]) <= radius) white.at(x, y) += float(level);
      }
    }
  }
  return white;
}

}  // namespace plenopiv::testing_support
