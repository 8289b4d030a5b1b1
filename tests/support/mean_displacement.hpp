// Tests: the mean displacement (dx, dy, dz) over a vector field's valid vectors, and how many.
#pragma once

#include <algorithm>
#include <array>
#include <cstddef>

#include "core/base/grid.hpp"

namespace plenopiv::testing_support {

struct MeanDisplacement {
  std::array<double, 3> mm{0, 0, 0};  // mean over the valid vectors (0 when none is valid)
  std::size_t valid = 0;
};

inline MeanDisplacement mean_displacement(const VectorField& f) {
  MeanDisplacement m;
  for (std::size_t i = 0; i < f.grid.count(); ++i) {
    if (!f.valid[i]) continue;
    ++m.valid;
    m.mm[0] += f.dx_mm[i];
    m.mm[1] += f.dy_mm[i];
    m.mm[2] += f.dz_mm[i];
  }
  for (double& v : m.mm) v /= double(std::max<std::size_t>(m.valid, 1));
  return m;
}

}  // namespace plenopiv::testing_support
