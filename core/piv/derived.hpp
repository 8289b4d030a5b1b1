// Fields derived from a vector field: vorticity from central differences on the vector grid.
#pragma once

#include <array>
#include <vector>

#include "core/base/grid.hpp"

namespace plenopiv::piv {

// Vorticity (1/s) of the velocity displacement / dt_s: x, y, z components on the field's grid,
// [z][y][x]. Central differences between valid neighbours, one-sided where only one side is
// valid; NaN at invalid nodes and where a derivative has no valid neighbour. dt_s must be > 0
// (InputError otherwise).
std::array<std::vector<float>, 3> vorticity(const VectorField& field);

}  // namespace plenopiv::piv
