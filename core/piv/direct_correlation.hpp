// A window pair's cyclic cross-correlation at shift 0 and its six face neighbours, summed directly.
#pragma once

#include <array>
#include <span>
#include <vector>

namespace plenopiv::piv {

// The star's shifts, in the order correlate_star gives them: (0, 0, 0), (-1, 0, 0), (1, 0, 0),
// (0, -1, 0), (0, 1, 0), (0, 0, -1), (0, 0, 1) (x, y, z; b at x + shift against a at x).
inline constexpr int kStarShifts = 7;

// The correlation FftCorrelator::Workspace::correlate gives (no spectral weights) at shift 0 and
// its six face neighbours, the values a three-point peak fit at shift 0 reads: R(s) = sum_x a'(x)
// b'((x + s) mod n), a' and b' the windows less their means, cyclic per axis like the transform's;
// the same sums to float rounding at 7 shifts instead of all of them. `a` and `b` are windows of
// `shape` ([z][y][x], x fastest), each size >= 3. `scratch` is grown on first use and reused. Built
// per instruction set with the same operations in the same order per value: the same bits on every
// path.
std::array<float, kStarShifts> correlate_star(std::span<const float> a, std::span<const float> b,
                                              const std::array<int, 3>& shape, std::vector<float>& scratch);

}  // namespace plenopiv::piv
