// Fields derived from a vector field: vorticity from central differences on the vector grid.
#include "core/piv/derived.hpp"

#include <cmath>
#include <limits>
#include <string>

#include "core/base/errors.hpp"

namespace plenopiv::piv {

std::array<std::vector<float>, 3> vorticity(const VectorField& f) {
  if (!(f.dt_s > 0)) throw InputError("vorticity: dt_s must be > 0, got " + std::to_string(f.dt_s));
  const Grid3& g = f.grid;
  const std::array<const std::vector<float>*, 3> comp{&f.dx_mm, &f.dy_mm, &f.dz_mm};
  const float nan = std::numeric_limits<float>::quiet_NaN();
  // d(component c)/d(axis a) in (mm / dt) per mm = 1/s: displacement mm over spacing mm over dt.
  auto derivative = [&](int c, int a, int x, int y, int z) -> double {
    std::array<int, 3> lo{x, y, z}, hi{x, y, z};
    --lo[a];
    ++hi[a];
    const bool has_lo = lo[a] >= 0 && f.valid[g.index(lo[0], lo[1], lo[2])];
    const bool has_hi = hi[a] < g.shape[a] && f.valid[g.index(hi[0], hi[1], hi[2])];
    const auto& v = *comp[c];
    const double centre = v[g.index(x, y, z)];
    double diff, dist;
    if (has_lo && has_hi) {
      diff = v[g.index(hi[0], hi[1], hi[2])] - v[g.index(lo[0], lo[1], lo[2])];
      dist = 2;
    } else if (has_hi) {
      diff = v[g.index(hi[0], hi[1], hi[2])] - centre;
      dist = 1;
    } else if (has_lo) {
      diff = centre - v[g.index(lo[0], lo[1], lo[2])];
      dist = 1;
    } else {
      return std::numeric_limits<double>::quiet_NaN();
    }
    return diff / (dist * g.spacing_mm[a] * f.dt_s);
  };
  std::array<std::vector<float>, 3> w;
  for (auto& c : w) c.assign(g.count(), nan);
  for (int z = 0; z < g.shape[2]; ++z)
    for (int y = 0; y < g.shape[1]; ++y)
      for (int x = 0; x < g.shape[0]; ++x) {
        const std::size_t i = g.index(x, y, z);
        if (!f.valid[i]) continue;
        // omega = curl(u): (dw/dy - dv/dz, du/dz - dw/dx, dv/dx - du/dy).
        w[0][i] = float(derivative(2, 1, x, y, z) - derivative(1, 2, x, y, z));
        w[1][i] = float(derivative(0, 2, x, y, z) - derivative(2, 0, x, y, z));
        w[2][i] = float(derivative(1, 0, x, y, z) - derivative(0, 1, x, y, z));
      }
  return w;
}

}  // namespace plenopiv::piv
