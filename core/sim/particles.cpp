// Synthetic particle fields: seeded uniform positions in a box, and seeding densities as counts.
#include "core/sim/particles.hpp"

#include <cmath>
#include <random>
#include <string>

#include "core/base/errors.hpp"

namespace plenopiv::sim {
namespace {

void check_box(const Box& box) {
  static const char* axes[3] = {"x", "y", "z"};
  for (int a = 0; a < 3; ++a) {
    if (!std::isfinite(box.min_mm[a]) || !std::isfinite(box.max_mm[a]) || !(box.max_mm[a] > box.min_mm[a])) {
      throw InputError(std::string("particle box: ") + axes[a] + " range [" + std::to_string(box.min_mm[a]) + ", " +
                       std::to_string(box.max_mm[a]) + "] mm is empty or not finite");
    }
  }
}

void check_density(double density, const char* unit) {
  if (!std::isfinite(density) || density < 0) {
    throw InputError(std::string("particle density: must be a finite number >= 0 ") + unit + ", got " +
                     std::to_string(density));
  }
}

// 53 random bits to a double in [0, 1): exact and the same on every platform.
double unit_interval(std::uint64_t bits) { return double(bits >> 11) * 0x1.0p-53; }

}  // namespace

std::vector<Point3> random_particles(const Box& box, std::size_t count, std::uint64_t seed) {
  check_box(box);
  std::mt19937_64 engine(seed);
  std::vector<Point3> points(count);
  for (Point3& p : points) {
    for (int a = 0; a < 3; ++a) {
      p[a] = box.min_mm[a] + unit_interval(engine()) * (box.max_mm[a] - box.min_mm[a]);
    }
  }
  return points;
}

std::vector<Point3> particles_around(const Grid3& grid, std::uint64_t seed, double per_voxel, int margin_voxels) {
  Box box;
  double voxels = 1;
  for (int a = 0; a < 3; ++a) {
    const int across = grid.shape[a] - 1 + margin_voxels;  // voxels from the first centre to the far face
    box.min_mm[a] = grid.origin_mm[a] - margin_voxels * grid.spacing_mm[a];
    box.max_mm[a] = grid.origin_mm[a] + across * grid.spacing_mm[a];
    voxels *= across + margin_voxels;
  }
  return random_particles(box, std::size_t(per_voxel * voxels), seed);
}

double field_of_view_area_ratio(const optics::CameraModel& camera, const Box& box) {
  check_box(box);
  const double box_area = (box.max_mm[0] - box.min_mm[0]) * (box.max_mm[1] - box.min_mm[1]);
  return box_area / (camera.field_of_view_x_mm() * camera.field_of_view_y_mm());
}

std::size_t particle_count_from_ppm(const optics::CameraModel& camera, const Box& box, double ppm) {
  check_density(ppm, "particles per microlens");
  return std::size_t(std::llround(ppm * camera.lens_count() * field_of_view_area_ratio(camera, box)));
}

std::size_t particle_count_from_ppp(const optics::CameraModel& camera, const Box& box, double ppp) {
  check_density(ppp, "particles per pixel");
  const double pixels = double(camera.sensor().width_px) * camera.sensor().height_px;
  return std::size_t(std::llround(ppp * pixels * field_of_view_area_ratio(camera, box)));
}

Box field_of_view_box(const optics::CameraModel& camera, double z_min_mm, double z_max_mm) {
  const double hx = 0.5 * camera.field_of_view_x_mm(), hy = 0.5 * camera.field_of_view_y_mm();
  return Box{{-hx, -hy, z_min_mm}, {hx, hy, z_max_mm}};
}

}  // namespace plenopiv::sim
