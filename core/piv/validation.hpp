// Vector validation: normalised median test (Westerweel & Scarano 2005) on a cubic
// neighbourhood, replacement by the second or third correlation peak, else by valid neighbours.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

namespace plenopiv::piv {

// Up to three candidate displacements per node (voxels, x y z; total, predictor included), best
// first, as the correlation found them. peaks[n] = 0 marks a window without signal.
struct Candidates {
  std::array<int, 3> count{0, 0, 0};
  std::array<std::vector<std::array<float, 3>>, 3> peak;  // [rank][node]
  std::vector<std::uint8_t> peaks;                        // candidates found per node, 0..3
  std::vector<std::uint8_t> flags;                        // VectorFlag bits per node

  explicit Candidates(std::array<int, 3> n = {0, 0, 0});
  std::size_t size() const { return std::size_t(count[0]) * count[1] * count[2]; }
};

struct MedianTest {
  double threshold = 2.0;  // normalised residual above which a vector is an outlier
  double epsilon = 0.1;    // voxels: the expected noise floor of the residuals
  int radius = 2;          // neighbourhood (2 r + 1)^3: 5x5x5
};

struct ValidationCounts {
  std::size_t outliers = 0;      // primary peaks that failed the median test
  std::size_t second_peak = 0;   // ... replaced by the second peak
  std::size_t third_peak = 0;    // ... replaced by the third peak
  std::size_t interpolated = 0;  // ... replaced by the mean of valid neighbours
  std::size_t unresolved = 0;    // ... left invalid (no valid neighbour)
};

// The validated field: one displacement per node and its validity.
struct ValidatedField {
  std::vector<std::array<float, 3>> d;
  std::vector<std::uint8_t> valid;
  ValidationCounts counts;
};

// Runs the test on every node's primary peak against its neighbours' primary peaks (nodes with
// signal, centre excluded): per component, r = |u - median| / (median |u_i - median| + epsilon),
// an outlier when any component's r exceeds the threshold. An outlier takes the second, else the
// third peak when that passes the same test; else the mean of the valid vectors in its 3x3x3
// neighbourhood (5x5x5 when none); else it stays invalid. Nodes without signal stay invalid.
// Updates `c.flags`. Parallel over nodes (TBB); deterministic.
ValidatedField validate(Candidates& c, const MedianTest& test);

// After validate(c, test) gave `f`: the outliers `nodes`, left to their neighbours (flagged
// interpolated or unresolved), have gained secondary peaks in `c`, and nothing else in `c` has
// changed (their primaries neither). Each takes its second, else third peak where that passes the
// test, and the outliers still left to their neighbours within reach of one that did are
// interpolated again; `f`, its counts and `c.flags` come out as validate(c, test) would give them
// afresh, without testing every node again. std::logic_error for a node that was not such an
// outlier. Serial: meant for a few nodes.
void revalidate_outliers(Candidates& c, const MedianTest& test, std::span<const std::size_t> nodes, ValidatedField& f);

// Smooths the valid vectors in place: `passes` binomial [1 2 1]/4 passes along x, y and z in turn.
// Along an axis a node is smoothed only where it and both its neighbours on that axis are valid;
// elsewhere (at the field's faces, beside an invalid node) it keeps its value, so a linear field
// comes out unchanged everywhere and nothing is taken from invalid nodes, which stay invalid with
// their values. Parallel over nodes (TBB); deterministic.
void smooth_valid(ValidatedField& f, std::array<int, 3> count, int passes);

// Fills invalid nodes (for use as a predictor) with the mean of valid nodes in the 5x5x5
// neighbourhood, or zero when there is none.
std::vector<std::array<float, 3>> fill_invalid(const ValidatedField& f, std::array<int, 3> count);

}  // namespace plenopiv::piv
