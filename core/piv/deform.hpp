// Window deformation: a displacement predictor on the vector grid, interpolated to every voxel,
// and both volumes resampled symmetrically with a 7x7x7 windowed-sinc (cardinal) interpolator.
#pragma once

#include <array>
#include <cstddef>
#include <span>
#include <utility>
#include <vector>

namespace plenopiv::piv {

// Displacement in voxels on a regular lattice of window centres, in the volume's voxel
// coordinates (voxel i's centre is at coordinate i). Arrays [z][y][x], x fastest.
struct NodeField {
  std::array<int, 3> count{0, 0, 0};
  std::array<double, 3> first{0, 0, 0};  // coordinate of node 0 per axis (voxels)
  std::array<double, 3> step{1, 1, 1};   // voxels between nodes per axis
  std::array<std::vector<float>, 3> d;   // displacement x, y, z (voxels)

  NodeField() = default;
  NodeField(std::array<int, 3> n, std::array<double, 3> first_node, std::array<double, 3> node_step);
  std::size_t size() const { return std::size_t(count[0]) * count[1] * count[2]; }
  std::size_t index(int i, int j, int k) const { return (std::size_t(k) * count[1] + j) * count[0] + i; }
  // Trilinear interpolation at voxel coordinates (x, y, z), in double and rounded to float once;
  // constant beyond the outer nodes.
  std::array<float, 3> at(double x, double y, double z) const;
  // Lower node and fraction towards the next one of coordinate p along `axis` (what at()
  // interpolates between; the deformation locates each voxel row and column once).
  std::pair<int, double> locate(int axis, double p) const;
  // Weight of each node along `axis` in the mean of that interpolant over the voxels
  // first_voxel .. first_voxel + n - 1. The mean over a box of voxels is the tensor product of
  // the three axes' weights: what a window that was deformed by this predictor has been moved by.
  std::vector<double> mean_weights(int axis, int first_voxel, int n) const;
};

// The cardinal interpolator: for a sample at voxel coordinate p, the 7 taps are the voxels
// round(p) - 3 ... round(p) + 3, weighted by sinc(t) * (1 + cos(pi t / 3.5)) / 2 (Hann-windowed
// sinc, half-width 3.5) with t = p - tap, normalised to sum 1 so a constant stays constant.
// Chosen over Lanczos windows by measurement: worst error 2e-3 for sines of period 7-20 voxels
// (Lanczos-4 on 7 taps: 2e-2, no better than trilinear). Weights come from a table at
// 1/256-voxel steps, linearly interpolated (error < 1e-5).
inline constexpr int sinc_taps = 7;
// Fills `w` with the weights for the fractional offset f = p - round(p) in [-0.5, 0.5].
void sinc7_weights(double f, std::array<float, sinc_taps>& w);

// Value of `volume` (shape nx, ny, nz; [z][y][x]) at voxel coordinates (x, y, z); voxels outside
// the volume count as 0.
float sample_sinc7(std::span<const float> volume, const std::array<int, 3>& shape, double x, double y, double z);

// Smooths a volume with the binomial kernel [1 2 1] / 4 along x, y and z (a Gaussian of sigma
// ~0.7 voxel; the edges use the kernel's inner taps only). Why: exact and reconstructed particles
// are only ~3 voxels wide, and their spectrum reaches the Nyquist frequency, where any short
// interpolator's phase is wrong; shifting both volumes by +-d/2 then biases the residual, most at
// half a voxel's shift. This filter removes that bias (docs/benchmarks.md, "Uniform shifts").
// `depth_passes` more [1 2 1] / 4 passes along z only follow (CorrelationSettings::
// depth_prefilter: a reconstructed particle is ~4 times as long in depth as wide, so a volume's
// depth detail finer than that is noise). `scratch` holds one volume. Parallel over z (TBB);
// deterministic.
void binomial_smooth(std::span<const float> in, const std::array<int, 3>& shape, std::span<float> out,
                     std::span<float> scratch, int depth_passes = 0);

// out = max(0, in - multiple * mean(in)): every voxel loses a floor proportional to the volume's
// mean intensity, and what lies below it becomes zero. Why (CorrelationSettings::
// intensity_threshold_of_mean): a reconstruction's ghost intensity is a faint haze along lines of
// sight that barely moves between the exposures and pulls the depth displacement toward zero; the
// particles stand well above it. Returns the floor subtracted. The mean is summed per z-slice in
// parallel and the slices in order: the same bits at any thread count. `in` and `out` may alias.
float subtract_mean_floor(std::span<const float> in, const std::array<int, 3>& shape, double multiple,
                          std::span<float> out);

// The deformation's interpolator. sinc: the 7x7x7 cardinal interpolator above. cubic: Keys'
// cubic convolution (Catmull-Rom) on a 4x4x4 stencil (64 voxels per sample, not 343); it reproduces
// quadratics but damps and shifts detail near the Nyquist frequency more, so it is for passes
// whose result only feeds the next pass's predictor (CorrelationSettings::early_interpolation).
enum class Interpolation { sinc, cubic };

// Symmetric deformation (Scarano & Poelma's VODIM): with d the predictor at voxel x,
// a_out(x) = a(x - d/2) and b_out(x) = b(x + d/2), so a particle displaced by d appears at the
// same place in both outputs. Parallel over z-slices (TBB); deterministic.
void deform_pair(std::span<const float> a, std::span<const float> b, const std::array<int, 3>& shape,
                 const NodeField& predictor, std::span<float> a_out, std::span<float> b_out,
                 Interpolation interpolation = Interpolation::sinc);

}  // namespace plenopiv::piv
