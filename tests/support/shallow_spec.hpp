// The volume and correlation keys of a processing spec on the small camera whose depth shifts MART
// can follow: process.yaml's settings with fewer passes (a test's time), the box on one side of the
// focal plane.
#pragma once

namespace plenopiv::testing_support {

// A spec's `volume:` and `correlation:` keys; the test adds dt_s and `reconstruction:`.
inline constexpr const char* kShallowSmallBox = R"(
volume: {x_mm: [-2, 2], y_mm: [-2, 2], z_mm: [0, 4], voxel_mm: 0.125, voxel_z_mm: 0.25, depth_guard_mm: 1}
correlation:
  passes: [{window: [32, 32, 16], overlap_percent: 50}, {window: [16, 16, 8], overlap_percent: 50, depth_margin: 2},
           {window: [16, 16, 8], overlap_percent: 75}]
  intensity_threshold_of_mean: 3
  depth_prefilter: 1
  final_smoothing: 1
)";

}  // namespace plenopiv::testing_support
