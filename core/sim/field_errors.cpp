// Vector-field errors against a flow's exact midpoint displacement (see field_errors.hpp).
#include "core/sim/field_errors.hpp"

#include <algorithm>
#include <cmath>

#include "core/base/errors.hpp"

namespace plenopiv::sim {

namespace {

// The exact displacement of the particle at `x` mid-way between the pulses (fixed-point iterations
// of the midpoint rule; 0: the displacement at x).
Point3 exact_displacement(const Flow& flow, const Point3& x, int midpoint_iterations) {
  Point3 d = flow.displacement_mm(x);
  for (int it = 0; it < midpoint_iterations; ++it)
    d = flow.displacement_mm({x[0] - d[0] / 2, x[1] - d[1] / 2, x[2] - d[2] / 2});
  return d;
}

}  // namespace

FieldErrors field_errors(const VectorField& field, const Flow& flow, double voxel_mm, int midpoint_iterations,
                         int border) {
  return field_errors(field, flow, voxel_mm, midpoint_iterations, border, {});
}

bool in_ring_axis_band(const RingVortexFlow& flow, const Point3& node_mm, double half_window_mm) {
  const Point3& c = flow.parameters().centre_mm;
  return std::abs(node_mm[0] - c[0]) <= half_window_mm && std::abs(node_mm[2] - c[2]) <= half_window_mm;
}

FieldErrors field_errors(const VectorField& field, const Flow& flow, double voxel_mm, int midpoint_iterations,
                         int border, const std::function<bool(const Point3&)>& include) {
  const Grid3& g = field.grid;
  FieldErrors e;
  std::array<double, 3> sum{0, 0, 0}, sum_sq{0, 0, 0}, sum_mt{0, 0, 0}, sum_tt{0, 0, 0};
  for (int k = border; k < g.shape[2] - border; ++k)
    for (int j = border; j < g.shape[1] - border; ++j)
      for (int i = border; i < g.shape[0] - border; ++i) {
        const std::size_t m = g.index(i, j, k);
        if (!field.valid[m]) continue;
        const Point3 x{g.coordinate_mm(0, i), g.coordinate_mm(1, j), g.coordinate_mm(2, k)};
        if (include && !include(x)) continue;
        const Point3 d = exact_displacement(flow, x, midpoint_iterations);
        const std::array<double, 3> got{field.dx_mm[m], field.dy_mm[m], field.dz_mm[m]};
        double truth_sq = 0;
        for (int a = 0; a < 3; ++a) {
          const double err = (got[a] - d[a]) / voxel_mm;
          sum[a] += err;
          sum_sq[a] += err * err;
          sum_mt[a] += got[a] * d[a];
          sum_tt[a] += d[a] * d[a];
          truth_sq += d[a] * d[a];
        }
        e.max_truth_voxels = std::max(e.max_truth_voxels, std::sqrt(truth_sq) / voxel_mm);
        ++e.compared;
      }
  if (e.compared == 0) {  // no valid node: no error figure, not a perfect one
    e.bias.fill(NAN);
    e.rms.fill(NAN);
    e.gain.fill(NAN);
    e.truth_rms.fill(NAN);
    e.rms_total = NAN;
    return e;
  }
  const double n = double(e.compared);
  for (int a = 0; a < 3; ++a) {
    e.bias[a] = sum[a] / n;
    e.rms[a] = std::sqrt(sum_sq[a] / n);
    e.gain[a] = sum_tt[a] > 0 ? sum_mt[a] / sum_tt[a] : NAN;
    e.truth_rms[a] = std::sqrt(sum_tt[a] / n) / voxel_mm;
  }
  e.rms_total = std::sqrt((sum_sq[0] + sum_sq[1] + sum_sq[2]) / n);
  return e;
}

UncertaintyCheck uncertainty_check(const VectorField& field, const Flow& flow, double voxel_mm, int midpoint_iterations,
                                   int border, const std::function<bool(const Point3&)>& include) {
  const Grid3& g = field.grid;
  const std::array<const std::vector<float>*, 3> sigma{&field.sigma_dx_mm, &field.sigma_dy_mm, &field.sigma_dz_mm};
  for (const auto* s : sigma)
    if (s->size() != g.count()) throw InputError("uncertainty check: the vector field has no per-vector sigma");
  UncertaintyCheck c;
  std::array<double, 3> err_sum{0, 0, 0}, err_sq{0, 0, 0}, sigma_sq{0, 0, 0}, in1{0, 0, 0}, in2{0, 0, 0};
  for (int k = border; k < g.shape[2] - border; ++k)
    for (int j = border; j < g.shape[1] - border; ++j)
      for (int i = border; i < g.shape[0] - border; ++i) {
        const std::size_t m = g.index(i, j, k);
        if (!field.valid[m]) continue;
        if (!(std::isfinite((*sigma[0])[m]) && std::isfinite((*sigma[1])[m]) && std::isfinite((*sigma[2])[m])))
          continue;
        const Point3 x{g.coordinate_mm(0, i), g.coordinate_mm(1, j), g.coordinate_mm(2, k)};
        if (include && !include(x)) continue;
        const Point3 d = exact_displacement(flow, x, midpoint_iterations);
        const std::array<double, 3> got{field.dx_mm[m], field.dy_mm[m], field.dz_mm[m]};
        for (int a = 0; a < 3; ++a) {
          const double signed_err = (got[a] - d[a]) / voxel_mm, err = std::abs(signed_err);
          const double s = (*sigma[a])[m] / voxel_mm;
          err_sum[a] += signed_err;
          err_sq[a] += err * err;
          sigma_sq[a] += s * s;
          in1[a] += err <= s;
          in2[a] += err <= 2 * s;
        }
        ++c.compared;
      }
  const double n = double(c.compared);
  for (int a = 0; a < 3; ++a) {
    c.rms_error[a] = c.compared ? std::sqrt(err_sq[a] / n) : NAN;
    c.bias[a] = c.compared ? err_sum[a] / n : NAN;
    c.rms_sigma[a] = c.compared ? std::sqrt(sigma_sq[a] / n) : NAN;
    c.within_1[a] = c.compared ? in1[a] / n : NAN;
    c.within_2[a] = c.compared ? in2[a] / n : NAN;
  }
  return c;
}

}  // namespace plenopiv::sim
