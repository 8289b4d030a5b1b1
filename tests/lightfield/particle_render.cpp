// Test support: raw plenoptic images of point particles, traced ray by ray.
#include "tests/lightfield/particle_render.hpp"

#include <cmath>

namespace plenopiv::testing_support {

ImagePoint image_point(const optics::CameraModel& camera, const PointParticle& p) {
  const double f = camera.main_lens().focal_length_mm;
  const double s_o = camera.object_distance_mm() + p.z_mm;
  const double s_i2 = f * s_o / (s_o - f);
  const double m = -s_i2 / s_o;  // the main lens inverts
  return {m * p.x_mm, m * p.y_mm, s_i2 / camera.image_distance_mm()};
}

ImageF render_particles(const optics::CameraModel& camera, const optics::MicrolensArray& lenses,
                        const std::vector<PointParticle>& particles, int n) {
  const auto& s = camera.sensor();
  const auto& l = lenses.lattice;
  const double s_i = camera.image_distance_mm(), f_l = camera.microlens().focal_length_mm;
  const double radius = 0.5 * camera.aperture_diameter_mm();
  const double c = std::cos(l.rotation_rad), sn = std::sin(l.rotation_rad);
  const bool hex = l.layout == optics::LensletLayout::hex;
  ImageF image(s.width_px, s.height_px, 0.0f);
  for (const PointParticle& p : particles) {
    const ImagePoint ip = image_point(camera, p);
    std::vector<std::array<double, 2>> aperture;
    for (int a = 0; a < n; ++a) {
      for (int b = 0; b < n; ++b) {
        const double u = (a + 0.5 - 0.5 * n) * 2 * radius / n, v = (b + 0.5 - 0.5 * n) * 2 * radius / n;
        if (u * u + v * v <= radius * radius) aperture.push_back({u, v});
      }
    }
    const double per_ray = p.intensity / double(aperture.size());
    for (const auto& uv : aperture) {
      const double k = 1 - 1 / ip.alpha;
      const double xm = uv[0] * k + ip.x_mm / ip.alpha, ym = uv[1] * k + ip.y_mm / ip.alpha;  // eq 2
      // Nearest lens centre among the lattice neighbours of the point.
      const double dx = xm - l.offset_x_mm, dy = ym - l.offset_y_mm;
      const double bj = (sn * dx + c * dy) / l.pitch_y_mm + 0.5 * (l.count_y - 1);
      const double ai = (c * dx - sn * dy) / l.pitch_x_mm + 0.5 * (l.count_x - 1);
      double best = 1e300;
      std::array<double, 2> centre{};
      for (int j = int(std::floor(bj)) - 1; j <= int(std::floor(bj)) + 2; ++j) {
        if (j < 0 || j >= l.count_y) continue;
        const double ic = ai - (hex ? ((j & 1) ? 0.25 : -0.25) : 0.0);
        for (int i = int(std::floor(ic)) - 1; i <= int(std::floor(ic)) + 2; ++i) {
          if (i < 0 || i >= l.count_x) continue;
          const auto& q = lenses.centre(i, j);
          const double d = (q[0] - xm) * (q[0] - xm) + (q[1] - ym) * (q[1] - ym);
          if (d < best) {
            best = d;
            centre = q;
          }
        }
      }
      if (best == 1e300) continue;
      // Thin microlens, sensor one focal length behind: x_s = c + f_l (x_m - u) / s_i.
      const double col = optics::sensor_mm_to_column(s, centre[0] + f_l * (xm - uv[0]) / s_i);
      const double row = optics::sensor_mm_to_row(s, centre[1] + f_l * (ym - uv[1]) / s_i);
      const int c0 = int(std::floor(col)), r0 = int(std::floor(row));
      const double tc = col - c0, tr = row - r0;
      for (int q = 0; q < 4; ++q) {
        const int x = c0 + (q & 1), y = r0 + (q >> 1);
        if (x < 0 || y < 0 || x >= s.width_px || y >= s.height_px) continue;
        const double w = ((q & 1) ? tc : 1 - tc) * ((q >> 1) ? tr : 1 - tr);
        image.at(x, y) += float(per_ray * w);
      }
    }
  }
  return image;
}

}  // namespace plenopiv::testing_support
