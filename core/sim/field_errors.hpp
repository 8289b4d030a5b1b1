// How far a measured vector field is from a flow's exact displacement: bias and RMS per component
// in voxels, the yardstick of every accuracy test and benchmark that knows its flow.
#pragma once

#include <array>
#include <cstddef>
#include <functional>

#include "core/base/grid.hpp"
#include "core/sim/flows.hpp"

namespace plenopiv::sim {

struct FieldErrors {
  std::array<double, 3> bias{0, 0, 0};  // mean error per component, voxels
  std::array<double, 3> rms{0, 0, 0};   // RMS error per component, voxels
  // Least-squares slope of measured against true displacement per component, sum(m t) / sum(t^2):
  // below 1 where a measurement falls short in proportion to the motion (NaN where the truth is 0).
  std::array<double, 3> gain{0, 0, 0};
  std::array<double, 3> truth_rms{0, 0, 0};  // RMS of the true displacement per component, voxels
  double rms_total = 0;                      // RMS of the error vector's length, voxels
  double max_truth_voxels = 0;               // largest true displacement among the nodes compared
  std::size_t compared = 0;                  // valid nodes compared (bias and RMS are NaN when none)
};

// Errors of the valid vectors of `field` against `flow`. The truth at a node x is the displacement
// of the particle whose move is centred on x (what a symmetric correlation measures):
// d = D(x - d/2), from d = D(x) by `midpoint_iterations` fixed-point steps. `border` node layers at
// every face are left out.
FieldErrors field_errors(const VectorField& field, const Flow& flow, double voxel_mm, int midpoint_iterations = 1,
                         int border = 0);
// The same over the nodes (node centre in mm) for which `include` is true.
FieldErrors field_errors(const VectorField& field, const Flow& flow, double voxel_mm, int midpoint_iterations,
                         int border, const std::function<bool(const Point3&)>& include);

// How well a field's per-vector uncertainty (VectorField::sigma_*) predicts its true errors, per
// component, over the valid nodes with an estimate on all three axes (voxels; the truth as in
// field_errors).
struct UncertaintyCheck {
  std::array<double, 3> rms_error{0, 0, 0};  // RMS of the true error (bias included)
  std::array<double, 3> bias{0, 0, 0};       // mean error: what no per-vector sigma of random error sees
  std::array<double, 3> rms_sigma{0, 0, 0};  // RMS of the predicted sigma: the RMS error it forecasts
  std::array<double, 3> within_1{0, 0, 0};   // fraction of errors within +-1 sigma (68 % if Gaussian)
  std::array<double, 3> within_2{0, 0, 0};   // ... within +-2 sigma (95 %)
  std::size_t compared = 0;                  // nodes compared (the figures are NaN when none)
};
// `include`: as field_errors' (every node when empty). InputError when the field has no sigma.
UncertaintyCheck uncertainty_check(const VectorField& field, const Flow& flow, double voxel_mm, int midpoint_iterations,
                                   int border, const std::function<bool(const Point3&)>& include = {});

// The ring vortex's axis band: nodes whose cubic window (half-width `half_window_mm`) reaches the
// ring's axis, |x - x_c| <= h and |z - z_c| <= h. There, with DESIGN.md's reading, the exact radial
// displacement (u, w) changes sign across the axis (every core point is equally near), so the
// true field is discontinuous and a window can only measure the mean across the jump.
bool in_ring_axis_band(const RingVortexFlow& flow, const Point3& node_mm, double half_window_mm);

}  // namespace plenopiv::sim
