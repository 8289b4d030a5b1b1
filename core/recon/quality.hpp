// Reconstruction quality: the zero-mean quality factor Q* (eq 14) and sub-voxel particle
// positions from a 3D Gaussian fit of the reconstructed intensity.
#pragma once

#include <array>
#include <optional>

#include "core/base/grid.hpp"

namespace plenopiv::recon {

// Eq 14: correlation of the zero-mean reconstructed and exact volumes (same grid), in [-1, 1];
// 0 when either volume is constant. InputError if the grids differ.
double quality_factor(const Volume& reconstructed, const Volume& exact);

struct ParticleFit {
  std::array<double, 3> position_mm{0, 0, 0};     // fitted peak, object space
  std::array<double, 3> position_voxel{0, 0, 0};  // fractional voxel indices (x, y, z)
  float peak = 0;                                 // intensity of the brightest voxel
};

// Fits a Gaussian to the intensity around the brightest voxel within `half_size` voxels (x, y, z)
// of `guess_mm`: along each axis through the peak, ln I is fitted by a parabola (least squares
// over the contiguous voxels above a quarter of the peak, at most `half_size` away) and its vertex
// is the sub-voxel position. std::nullopt when the window holds no positive intensity.
std::optional<ParticleFit> fit_particle(const Volume& volume, const std::array<double, 3>& guess_mm,
                                        const std::array<int, 3>& half_size);

// The centre of a 3D Gaussian by the method of moments: the intensity-weighted mean position of
// the voxels within `lateral_radius` (x and y) and half_size[2] (z) of the brightest voxel within
// `half_size` of `guess_mm`. A reconstructed particle is stretched along the line of sight, tilted
// off the z axis away from the optical axis, and after many iterations its light gathers in a few
// sharp voxels along that streak: a fit through the peak's own column sees one or two of them,
// the moments see them all (docs/benchmarks.md, "Fig 22"). std::nullopt as fit_particle;
// InputError for a negative lateral_radius.
std::optional<ParticleFit> fit_particle_moments(const Volume& volume, const std::array<double, 3>& guess_mm,
                                                const std::array<int, 3>& half_size, int lateral_radius = 1);

}  // namespace plenopiv::recon
