// Synthetic particle fields: seeded uniform positions in a box, and seeding densities as counts.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <vector>

#include "core/base/grid.hpp"
#include "core/optics/camera_model.hpp"

namespace plenopiv::sim {

// A position in object space, mm: x right, y down, z away from the camera, z = 0 at the
// nominal focal plane (DESIGN.md).
using Point3 = std::array<double, 3>;

// An axis-aligned box in object space, mm. Particles may fill a box larger than the
// reconstructed volume, as seeding fills a real flow beyond what is reconstructed.
struct Box {
  Point3 min_mm{0, 0, 0};
  Point3 max_mm{0, 0, 0};
};

// `count` positions uniformly distributed in `box` (each coordinate uniform in [min, max)).
// The same (box, count, seed) gives the same positions on every machine: the generator is
// std::mt19937_64 and the mapping to [0, 1) is done here, not by a library distribution
// whose algorithm the standard leaves open. Throws InputError for an empty or inverted box.
std::vector<Point3> random_particles(const Box& box, std::size_t count, std::uint64_t seed);

// Exact-particle volumes at the paper's seeding: 0.5 ppm over the paper's camera is ~28 000
// particles in 300 x 200 x 200 voxels of 0.1 mm, 0.0023 per voxel.
inline constexpr double kPaperParticlesPerVoxel = 0.0023;
// Random particles (mm) for a volume on `grid`: `per_voxel` per voxel of a box reaching
// `margin_voxels` voxels beyond the outermost voxel centres on every side, so that particles enter
// and leave the volume's faces as in a real flow. Default: the paper's seeding, 4 voxels.
std::vector<Point3> particles_around(const Grid3& grid, std::uint64_t seed, double per_voxel = kPaperParticlesPerVoxel,
                                     int margin_voxels = 4);

// Seeding densities as particle counts. The paper quotes densities per microlens (ppm) and
// per pixel (ppp) over the whole image (sec 4.3: 0.5 ppm over 289 x 193 lenses, ~28 000
// particles, "or 0.0017 ppp"). Exact definitions used here:
//   ppm: count = round(ppm * lens_count * area_ratio)
//   ppp: count = round(ppp * width_px * height_px * area_ratio)
// where area_ratio = (box x-y area) / (field of view x-y area at the focal plane,
// CameraModel::field_of_view_x_mm() * field_of_view_y_mm()). The ratio keeps the density
// inside the field of view equal to the one asked for when the box reaches beyond it; for a
// box that matches the field of view (the paper's case) it is 1 and count = ppm * lens_count.
// Throws InputError for a negative or non-finite density or an empty box.
double field_of_view_area_ratio(const optics::CameraModel& camera, const Box& box);
std::size_t particle_count_from_ppm(const optics::CameraModel& camera, const Box& box, double ppm);
std::size_t particle_count_from_ppp(const optics::CameraModel& camera, const Box& box, double ppp);

// The box that exactly covers the camera's field of view laterally (centred on the optical
// axis) and spans [z_min_mm, z_max_mm] in depth.
Box field_of_view_box(const optics::CameraModel& camera, double z_min_mm, double z_max_mm);

}  // namespace plenopiv::sim
