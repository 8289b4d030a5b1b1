// The paper's baseline "exact-particle volume": every particle a 3x3x3 blob at its true position.
#pragma once

#include <span>

#include "core/base/grid.hpp"
#include "core/sim/particles.hpp"

namespace plenopiv::sim {

// Renders particles (mm) onto `grid` as 3x3x3-voxel blobs (paper secs 6.1, 6.4: "a 3x3x3
// Gaussian blob representing each particle"), the reference the reconstruction is compared
// with (Q*, eq 14) and the baseline volumes the PIV is run on.
//
// Blob: separable, w(x) w(y) w(z) over the 3 voxels around the nearest voxel, with per-axis
// taps at offsets -1, 0, +1 for a sub-voxel offset d in [-0.5, 0.5] of
//   w(-1) = (0.5 - d)^2 / 2,  w(0) = 0.75 - d^2,  w(+1) = (0.5 + d)^2 / 2,
// the quadratic B-spline (a box convolved with itself three times: the 3-tap Gaussian of
// sigma = 0.5 voxel). Why not a sampled Gaussian: 3 samples of a Gaussian pull the centroid
// towards the nearest voxel (by 0.045 voxel at d = 0.5 for sigma 0.6), while these taps put the
// centroid exactly at the true position, sum to 1 and have the same variance (0.25 voxel^2 per
// axis) for every sub-voxel position, so blobs look alike wherever the particle sits.
// Intensity: a particle exactly at a voxel centre gives that voxel the value `peak`
// (0.75^3 scaled to peak); every particle carries the same total intensity peak / 0.421875.
// Overlapping blobs add. Taps outside the grid are dropped (particles near or beyond the edge
// contribute what falls inside).
// Parallel over z slices with TBB; each slice sums its particles in a fixed order (by nearest
// slice, then input order), so the result is bit-identical at any thread count.
Volume render_exact_volume(const Grid3& grid, std::span<const Point3> particles_mm, float peak = 1.f);

}  // namespace plenopiv::sim
