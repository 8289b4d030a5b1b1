// Per-vector standard uncertainty from correlation statistics (Wieneke 2015) in 3D, and its
// propagation through the final field's smoothing (Sciacchitano & Wieneke 2016).
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <span>
#include <string>
#include <vector>

namespace plenopiv::piv {

// Buffers of one thread's uncertainty windows (grown on first use, reused after).
struct UncertaintyScratch {
  std::vector<float> a, rolled;  // the two windows, mean-subtracted; b rolled by the shift
  std::vector<float> delta;      // per-voxel asymmetry of the +-1 neighbours along one axis
  std::vector<float> box, line;  // box sums of delta, and its sums along x and y
};

// The standard uncertainty (voxels, x y z) of the sub-voxel peak position of one window's
// correlation, by the correlation-statistics method of Wieneke (Meas. Sci. Technol. 26 (2015)
// 074002), extended from 2D to 3D. `a` and `b` are the volumes the final pass correlated (deformed:
// matching where the predictor is right), `shape` theirs. The window holds the voxels `origin` ..
// origin + window - 1 of `a`; the second volume's reaches `depth_margin` slices further at each
// depth end (PassSettings::depth_margin), and the first's is zero there. Both are mean-subtracted
// and correlated cyclically, as FftCorrelator does, with the peak at the integer shift `shift`
// (b at x + shift matches a at x). For every voxel x and each axis e, the contributions
// a(x) b(x + shift + e) and a(x + e) b(x + shift) are x's shares of the correlation at the peak's
// +1 and -1 neighbours (cyclic sums, the same as the correlation's); their difference dC(x) sums to
// C(+1) - C(-1), which sets the peak's sub-voxel position, and is zero at every voxel when the two
// windows match exactly. Its fluctuation, sigma_dC^2 = sum_x dC'(x) sum_{y near x} dC'(y) (dC' the
// difference from its mean; `near`: within a box of about two Gaussian widths of the correlation
// peak per axis, because one particle pair's contributions are alike over its image), is carried
// through the 3-point Gaussian fit as an asymmetry of +-sigma_dC / 2 between C(+1) and C(-1)
// (parabolic where a value is not positive). With a depth margin the correlation the peak was
// found on was normalised per depth shift; these sums are the plain correlation's. NaN on an axis
// whose peak has no curvature (no estimate).
std::array<float, 3> correlation_statistics_sigma(std::span<const float> a, std::span<const float> b,
                                                  const std::array<int, 3>& shape, const std::array<int, 3>& origin,
                                                  const std::array<int, 3>& window, int depth_margin,
                                                  const std::array<int, 3>& shift, UncertaintyScratch& scratch);

// What correlation_statistics_sigma gives, computed every `stride` nodes per axis and interpolated
// between (1: at every node; CorrelationSettings::uncertainty_stride), carried through
// `smoothing_passes` of smooth_sigma (0: none), in words: a field's sigma_method.
std::string correlation_statistics_method(int stride, int smoothing_passes);

// Carries per-node standard uncertainties (one component, `sigma`, NaN: none) through
// smooth_valid's `passes` binomial [1 2 1]/4 passes, node for node with the same rule (a node is
// smoothed along an axis only where it and both neighbours there are valid). The errors of
// overlapping windows are correlated: along an axis, two windows k nodes apart share the fraction
// rho(k) = max(0, 1 - k step / window) of their voxels, and their errors are taken to be correlated
// by that fraction (top-hat windows, errors from voxel-scale noise: Sciacchitano & Wieneke, Meas.
// Sci. Technol. 27 (2016) 084006), so sigma'^2 = sum_ij w_i w_j rho(i - j) sigma_i sigma_j. Each
// axis pass uses the windows' overlap along that axis, which is exact for one pass of smoothing
// and slightly optimistic for more. A NaN neighbour makes the node NaN.
void smooth_sigma(std::vector<float>& sigma, std::span<const std::uint8_t> valid, std::array<int, 3> count, int passes,
                  const std::array<int, 3>& step, const std::array<int, 3>& window);

}  // namespace plenopiv::piv
