// Correlation peaks: the three highest local maxima and their sub-voxel positions.
#pragma once

#include <array>
#include <cstdint>
#include <span>

namespace plenopiv::piv {

// Per-vector flags (bits), stored beside the field: how the peak was fitted and what the
// validation did with it.
enum VectorFlag : std::uint8_t {
  flag_parabolic = 1,      // 3-point Gaussian impossible (a value <= 0): parabolic fit on an axis
  flag_centroid = 2,       // peak on the window border (|shift| = n/2): centroid on that axis
  flag_no_signal = 4,      // window without particle signal: skipped, invalid
  flag_second_peak = 8,    // median-test outlier replaced by the second correlation peak
  flag_third_peak = 16,    // ... by the third peak
  flag_interpolated = 32,  // ... by the mean of valid neighbours
  flag_unresolved = 64,    // outlier with no valid replacement: invalid
};

// The meaning of each VectorFlag bit, for files that store the flags ("1: ...; 2: ...").
inline constexpr const char* kVectorFlagLegend =
    "bits: 1 parabolic peak fit on an axis (3-point Gaussian impossible); 2 peak on the window border "
    "(centroid); 4 no particle signal (invalid); 8 outlier replaced by the second correlation peak; 16 by the "
    "third peak; 32 by the mean of valid neighbours; 64 outlier without a replacement (invalid); 0 a first-peak "
    "Gaussian fit that passed validation";

// One correlation peak: sub-voxel shift (voxels, x, y, z), the correlation value at its integer
// maximum, and how it was fitted (flag_parabolic / flag_centroid bits).
struct Peak {
  std::array<float, 3> shift{0, 0, 0};
  float value = 0;
  std::uint8_t flags = 0;
};

// Sub-voxel position of the maximum at integer index `at` (x, y, z) of a cyclic correlation
// `corr` ([z][y][x], shift 0 at index 0) of the given shape: 3-point Gaussian fit per axis; a
// parabolic fit where a value is <= 0, the centroid of the three values where the peak sits on
// the border of the unambiguous shift range (-n/2 or n/2 - 1).
Peak fit_peak(std::span<const float> corr, const std::array<int, 3>& shape, const std::array<int, 3>& at);

// The three highest local maxima (26-neighbourhood, cyclic) in decreasing order, each fitted by
// fit_peak. Only positive maxima count; missing peaks have value 0 and zero shift. Ties are broken
// by the lower index, so the result does not depend on anything but the input.
std::array<Peak, 3> find_peaks(std::span<const float> corr, const std::array<int, 3>& shape);

// Primary over secondary peak value, capped at `peak_ratio_cap` (also when the second peak is
// missing or not positive).
inline constexpr float peak_ratio_cap = 1000.f;
float peak_ratio(const std::array<Peak, 3>& peaks);

}  // namespace plenopiv::piv
