// Where the microlenses are: the lattice (pitch, rotation, offset, rect|hex) and per-lens centres.
#include "core/optics/microlens_array.hpp"

#include <cmath>

namespace plenopiv::optics {

Lattice Lattice::nominal(const CameraModel& camera) {
  Lattice l;
  l.layout = camera.microlens().layout;
  l.count_x = camera.nominal_count_x();
  l.count_y = camera.nominal_count_y();
  l.pitch_x_mm = camera.microlens().pitch_mm;
  l.pitch_y_mm = camera.row_pitch_mm();
  return l;
}

std::array<double, 2> Lattice::position(int i, int j) const {
  double a = i - 0.5 * (count_x - 1);
  if (layout == LensletLayout::hex) a += (j % 2) ? 0.25 : -0.25;
  a *= pitch_x_mm;
  const double b = (j - 0.5 * (count_y - 1)) * pitch_y_mm;
  const double c = std::cos(rotation_rad), s = std::sin(rotation_rad);
  // Counter-clockwise on the upright image (y down): +x turns towards -y.
  return {c * a + s * b + offset_x_mm, -s * a + c * b + offset_y_mm};
}

MicrolensArray MicrolensArray::from_lattice(const Lattice& lattice) {
  MicrolensArray array{lattice, {}};
  array.centres_mm.reserve(lattice.count());
  for (int j = 0; j < lattice.count_y; ++j) {
    for (int i = 0; i < lattice.count_x; ++i) array.centres_mm.push_back(lattice.position(i, j));
  }
  return array;
}

}  // namespace plenopiv::optics
