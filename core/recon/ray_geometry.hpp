// One ray of sec 5.2 along one sensor axis: the aperture sample (plaid grid), the two lenses that
// bracket it on the microlens plane (eq 11) and the two pixels behind each (eq 1 inverted), shared
// by the separable tables and the explicit reference matrix. Internal to core/recon.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <utility>
#include <vector>

#include "core/optics/microlens_array.hpp"
#include "core/recon/weights.hpp"

namespace plenopiv::recon::detail {

// Interpolation fractions this close to 0 or 1 are rounding noise of an exact hit.
inline constexpr double kSnap = 1e-9;

struct Hit {
  int index = -1;
  double weight = 0;
};

// Eq 11 in lattice coordinates: the two lenses whose centres bracket `x` and the linear weights
// (1 - t, t). Lattice coordinates are piecewise linear between measured centres; beyond the
// array's ends they continue with the edge pitch and the missing lens's share is lost.
inline std::pair<Hit, Hit> bracket(const std::vector<double>& centres, double x) {
  const int n = int(centres.size());
  if (n == 1) return {Hit{}, Hit{}};
  const auto it = std::upper_bound(centres.begin(), centres.end(), x);
  const int i1 = int(it - centres.begin());
  if (i1 == 0) {
    const double t = 1.0 + (x - centres[0]) / (centres[1] - centres[0]);
    return {Hit{}, t > 0 ? Hit{0, t} : Hit{}};
  }
  if (i1 == n) {
    const double t = (x - centres[n - 1]) / (centres[n - 1] - centres[n - 2]);
    return {t < 1 ? Hit{n - 1, 1.0 - t} : Hit{}, Hit{}};
  }
  const int i0 = i1 - 1;
  double t = (x - centres[i0]) / (centres[i1] - centres[i0]);
  if (t < kSnap) t = 0;
  if (t > 1 - kSnap) t = 1;
  return {Hit{i0, 1.0 - t}, Hit{i1, t}};
}

// Everything about one ray along one sensor axis: up to 2 lenses x 2 pixels (the 1-D factor of
// eq 12's 16 coefficients), written to out_pixel / out_weight (room for 4); returns how many.
// `pixel_of_mm` maps sensor mm to a fractional pixel index; `pixels` is the sensor's size along
// the axis (pixels beyond it are dropped).
template <typename PixelOf>
int ray_coefficients(const WeightingOperator::Geometry& g, const std::vector<double>& centres, double alpha,
                     double prime_mm, double u, int pixels, PixelOf pixel_of_mm, int* out_pixel, double* out_weight) {
  // Eq 2: where the ray from aperture point u through the image-space point x' meets the
  // microlens plane.
  const double x_ml = u * (1.0 - 1.0 / alpha) + prime_mm / alpha;
  const auto [a, b] = bracket(centres, x_ml);
  int count = 0;
  for (const Hit& lens : {a, b}) {
    if (lens.index < 0 || lens.weight <= 0) continue;
    // Eq 1 inverted: behind that lens the ray lands at spot - u f_l / s_i.
    const double spot = optics::lens_centre_to_spot_mm(centres[std::size_t(lens.index)], g.s_i, g.f_lens);
    const double p = pixel_of_mm(spot - u * g.f_lens / g.s_i);
    double p0 = std::floor(p);
    double t = p - p0;
    // Rounding must not turn an exact hit into a 1e-16 weight on the neighbour (it would widen
    // the voxel's footprint by a pixel that a dark test would then see).
    if (t < kSnap) t = 0;
    if (t > 1 - kSnap) {
      t = 0;
      p0 += 1;
    }
    const int i0 = int(p0);
    if (i0 >= 0 && i0 < pixels && t < 1) {
      out_pixel[count] = i0;
      out_weight[count++] = lens.weight * (1.0 - t);
    }
    if (i0 + 1 >= 0 && i0 + 1 < pixels && t > 0) {
      out_pixel[count] = i0 + 1;
      out_weight[count++] = lens.weight * t;
    }
  }
  return count;
}

// Aperture sample k of `samples` per axis: the centre of cell k of the plaid grid over the
// aperture diameter, mm from the optical axis.
inline double sample_position(double aperture, int samples, int k) {
  return (k + 0.5) * aperture / samples - 0.5 * aperture;
}

}  // namespace plenopiv::recon::detail
