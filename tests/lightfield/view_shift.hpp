// Tests: how far a particle moves between perspective views (sec 3.4) — the centroid of a view on
// the microlens plane and the least-squares slope of that centroid against the aperture point.
#pragma once

#include <array>

#include "core/base/image.hpp"
#include "core/lightfield/light_field.hpp"
#include "core/lightfield/refocus.hpp"
#include "core/optics/microlens_array.hpp"

namespace plenopiv::testing_support {

// Centroid of a view image on the microlens plane (mm), by lattice positions.
inline std::array<double, 2> centroid_mm(const ImageF& view, const optics::Lattice& lattice) {
  double s = 0, sx = 0, sy = 0;
  for (int j = 0; j < view.height; ++j) {
    for (int i = 0; i < view.width; ++i) {
      const double w = view.at(i, j);
      const auto q = lattice.position(i, j);
      s += w;
      sx += w * q[0];
      sy += w * q[1];
    }
  }
  return {sx / s, sy / s};
}

// Slopes (mm per mm of aperture) of the view centroid against u (v = 0) and against v (u = 0),
// from views at u = -u_max, -u_max + 1, ..., u_max mm. Eq 2 predicts 1 - 1/alpha for both.
inline std::array<double, 2> view_shift_slopes(const lightfield::LightField& field, const optics::Lattice& lattice,
                                               double u_max) {
  double su = 0, sx = 0, suu = 0, sux = 0, sy = 0, suy = 0;
  int n = 0;
  for (double u = -u_max; u <= u_max + 0.001; u += 1.0) {
    const auto cx = centroid_mm(lightfield::perspective_view(field, u, 0), lattice);
    const auto cy = centroid_mm(lightfield::perspective_view(field, 0, u), lattice);
    su += u;
    suu += u * u;
    sx += cx[0];
    sux += u * cx[0];
    sy += cy[1];
    suy += u * cy[1];
    ++n;
  }
  return {(n * sux - su * sx) / (n * suu - su * su), (n * suy - su * sy) / (n * suu - su * su)};
}

}  // namespace plenopiv::testing_support
