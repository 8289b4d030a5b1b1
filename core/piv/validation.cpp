// Vector validation: normalised median test, replacement by secondary peaks or neighbours.
#include "core/piv/validation.hpp"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>

#include "core/piv/peak_fit.hpp"

namespace plenopiv::piv {
namespace {

constexpr int max_radius = 3;
constexpr int max_neighbours = (2 * max_radius + 1) * (2 * max_radius + 1) * (2 * max_radius + 1);

float median(float* v, int n) {
  std::nth_element(v, v + n / 2, v + n);
  const float upper = v[n / 2];
  if (n % 2) return upper;
  return 0.5f * (upper + *std::max_element(v, v + n / 2));
}

// The neighbours' primary vectors per component, their median and, once a test needs it, the
// median absolute residual about it (the spread).
struct Reference {
  int n = 0;
  std::array<std::array<float, max_neighbours>, 3> values;  // reordered by the medians
  std::array<float, 3> median{0, 0, 0};
  std::array<float, 3> spread{0, 0, 0};
  bool has_spread = false;
};

template <typename Visit>
void for_neighbours(const std::array<int, 3>& count, std::size_t node, int radius, Visit visit) {
  const int i = int(node % count[0]);
  const int j = int((node / count[0]) % count[1]);
  const int k = int(node / (std::size_t(count[0]) * count[1]));
  for (int z = std::max(k - radius, 0); z <= std::min(k + radius, count[2] - 1); ++z)
    for (int y = std::max(j - radius, 0); y <= std::min(j + radius, count[1] - 1); ++y)
      for (int x = std::max(i - radius, 0); x <= std::min(i + radius, count[0] - 1); ++x) {
        const std::size_t m = (std::size_t(z) * count[1] + y) * count[0] + x;
        if (m != node) visit(m);
      }
}

// The neighbours' primary vectors into `ref`, without their medians yet.
void gather_reference(const Candidates& c, std::size_t node, int radius, Reference& ref) {
  ref.n = 0;
  ref.has_spread = false;
  for_neighbours(c.count, node, radius, [&](std::size_t m) {
    if (!c.peaks[m]) return;
    for (int a = 0; a < 3; ++a) ref.values[a][ref.n] = c.peak[0][m][a];
    ++ref.n;
  });
}

void find_medians(Reference& ref) {
  for (int a = 0; a < 3; ++a) ref.median[a] = median(ref.values[a].data(), ref.n);
}

// The float nearest `x` on the side of `toward`'s sign: at or above it (+1), at or below (-1).
float float_at_or(double x, int toward) {
  const float f = float(x);
  if (toward > 0 && double(f) < x) return std::nextafter(f, std::numeric_limits<float>::infinity());
  if (toward < 0 && double(f) > x) return std::nextafter(f, -std::numeric_limits<float>::infinity());
  return f;
}

// Whether `u` passes the test's first step (within threshold x epsilon of the median on every
// axis) whatever the medians' exact values, from counts alone: an axis's median lies in [lo, hi]
// when at most (n - 1) / 2 of the n values are below lo and at most as many above hi (for even n
// both middle values do, and so does their mean). [lo, hi] is u +- a hair less than threshold x
// epsilon, so passes()'s float arithmetic agrees. Counting is one vectorised pass over each axis's
// values where a median is a selection; a vector not surely near goes through the full test, so
// the outcome is that of passes() alone.
bool surely_near(const std::array<float, 3>& u, const Reference& ref, const MedianTest& test) {
  const double reach = test.threshold * test.epsilon * (1 - 1e-5);
  const int limit = (ref.n - 1) / 2;
  for (int a = 0; a < 3; ++a) {
    const float lo = float_at_or(double(u[a]) - reach, +1), hi = float_at_or(double(u[a]) + reach, -1);
    if (!(lo <= hi)) return false;  // u not finite, or no reach
    const float* v = ref.values[a].data();
    int below = 0, above = 0;
    for (int m = 0; m < ref.n; ++m) {
      below += v[m] < lo;
      above += v[m] > hi;
    }
    if (!(below <= limit && above <= limit)) return false;
  }
  return true;
}

// The spread from the values in whatever order the medians left them: a median is the same
// value in any order.
void find_spread(Reference& ref) {
  for (int a = 0; a < 3; ++a) {
    float* v = ref.values[a].data();
    for (int m = 0; m < ref.n; ++m) v[m] = std::abs(v[m] - ref.median[a]);
    ref.spread[a] = median(v, ref.n);
  }
  ref.has_spread = true;
}

// The second step on one axis: r = |u - median| against threshold x (spread + epsilon), in the
// arithmetic both the full test and the counts below use.
bool spread_step_holds(float r, float spread, const MedianTest& test) {
  return double(r) / (double(spread) + test.epsilon) <= test.threshold;
}

// The second step's outcome on axis `a` for the distance r = |u - median| from counts alone,
// where the spread (the median of the residuals |v - median|) is surely on one side of the
// smallest spread that passes: +1 surely passes, -1 surely fails, 0 not sure. The step's
// quotient r / (spread + epsilon) does not grow with the spread, so the test holds for every
// spread at or above a value where it holds (`high`), and fails for every spread at or below one
// where it fails (`low`); both are found near r / threshold - epsilon and checked with the step's
// own arithmetic. The spread is at or above `high` when at most (n - 1) / 2 residuals lie below
// it, and below `low` when at least n - (n - 1) / 2 do (for even n both middle values then lie on
// that side, and so does their mean): one vectorised pass over the values (finite: fitted
// shifts), where the spread is a selection.
int spread_step_by_counts(float r, const Reference& ref, int a, const MedianTest& test) {
  const auto holds = [&](float spread) { return spread_step_holds(r, spread, test); };
  if (!std::isfinite(r)) return 0;
  if (holds(0.f)) return +1;  // the spread is >= 0
  const double t = double(r) / test.threshold - test.epsilon;
  if (!(t < std::numeric_limits<float>::max())) return 0;  // no float bound: the full test
  float high = float(t), low = float(t);
  for (int k = 0; k < 4 && !holds(high); ++k) high = std::nextafter(high, std::numeric_limits<float>::infinity());
  for (int k = 0; k < 4 && holds(low); ++k) low = std::nextafter(low, -std::numeric_limits<float>::infinity());
  if (!holds(high) || holds(low)) return 0;
  const float median = ref.median[a];
  const float* v = ref.values[a].data();
  int below_high = 0, below_low = 0;
  for (int m = 0; m < ref.n; ++m) {
    const float residual = std::abs(v[m] - median);
    below_high += residual < high;
    below_low += residual < low;
  }
  const int limit = (ref.n - 1) / 2;
  if (below_high <= limit) return +1;
  if (below_low >= ref.n - limit) return -1;
  return 0;
}

bool passes(const std::array<float, 3>& u, Reference& ref, const MedianTest& test) {
  // Within threshold x epsilon of the median on every axis a vector passes whatever the spread
  // (>= 0, and a larger divisor gives no larger quotient): the spread's three selections are
  // needed only beyond, and the outcome is the full test's.
  bool near = true;
  for (int a = 0; a < 3; ++a)
    if (!(std::abs(u[a] - ref.median[a]) / test.epsilon <= test.threshold)) near = false;
  if (near) return true;
  if (!ref.has_spread) {
    // Counts decide most vectors without the spread's selections; an axis they leave unsure
    // takes the selections and the full test, so the outcome is the full test's.
    bool sure = true;
    for (int a = 0; a < 3; ++a) {
      const int step = spread_step_by_counts(std::abs(u[a] - ref.median[a]), ref, a, test);
      if (step < 0) return false;
      sure = sure && step > 0;
    }
    if (sure) return true;
    find_spread(ref);
  }
  for (int a = 0; a < 3; ++a)
    if (!spread_step_holds(std::abs(u[a] - ref.median[a]), ref.spread[a], test)) return false;
  return true;
}

// The mean of the vectors `valid(m)` says are valid in the neighbourhood; false where there is none.
template <typename Valid>
bool mean_of(const ValidatedField& f, const std::array<int, 3>& count, std::size_t node, int radius, Valid valid,
             std::array<float, 3>& out) {
  double sum[3] = {0, 0, 0};
  int n = 0;
  for_neighbours(count, node, radius, [&](std::size_t m) {
    if (!valid(m)) return;
    for (int a = 0; a < 3; ++a) sum[a] += f.d[m][a];
    ++n;
  });
  if (!n) return false;
  for (int a = 0; a < 3; ++a) out[a] = float(sum[a] / n);
  return true;
}

bool mean_of_valid(const ValidatedField& f, const std::array<int, 3>& count, std::size_t node, int radius,
                   std::array<float, 3>& out) {
  return mean_of(
      f, count, node, radius, [&](std::size_t m) { return f.valid[m] != 0; }, out);
}

// An outlier's replacement by its neighbours: the mean of the settled vectors (`settled(m)`) in
// its 3x3x3 neighbourhood, else in its 5x5x5; false where there is none.
template <typename Settled>
bool interpolate(const ValidatedField& f, const std::array<int, 3>& count, std::size_t node, Settled settled,
                 std::array<float, 3>& out) {
  return mean_of(f, count, node, 1, settled, out) || mean_of(f, count, node, 2, settled, out);
}

// The first of an outlier's secondary peaks (rank 1 or 2) that passes the test against `ref` (its
// medians found), or 0.
int passing_secondary(const Candidates& c, std::size_t node, Reference& ref, const MedianTest& test) {
  for (int rank = 1; rank < c.peaks[node]; ++rank)
    if (passes(c.peak[rank][node], ref, test)) return rank;
  return 0;
}

VectorFlag secondary_flag(int rank) { return rank == 1 ? flag_second_peak : flag_third_peak; }

}  // namespace

Candidates::Candidates(std::array<int, 3> n) : count(n) {
  for (auto& p : peak) p.assign(size(), {0, 0, 0});
  peaks.assign(size(), 0);
  flags.assign(size(), 0);
}

ValidatedField validate(Candidates& c, const MedianTest& test) {
  const std::size_t n = c.size();
  const int radius = std::clamp(test.radius, 1, max_radius);
  ValidatedField f;
  f.d.assign(n, {0, 0, 0});
  f.valid.assign(n, 0);
  // 0: passed, 1: outlier replaced by a peak, 2: outlier waiting for interpolation.
  std::vector<std::uint8_t> state(n, 0);
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n), [&](const auto& r) {
    Reference ref;
    for (std::size_t node = r.begin(); node < r.end(); ++node) {
      if (!c.peaks[node]) continue;
      gather_reference(c, node, radius, ref);
      const bool near = ref.n == 0 || surely_near(c.peak[0][node], ref, test);
      if (!near) find_medians(ref);
      if (near || passes(c.peak[0][node], ref, test)) {
        f.d[node] = c.peak[0][node];
        f.valid[node] = 1;
        continue;
      }
      state[node] = 2;
      if (const int rank = passing_secondary(c, node, ref, test)) {
        f.d[node] = c.peak[rank][node];
        f.valid[node] = 1;
        c.flags[node] |= secondary_flag(rank);
        state[node] = 1;
      }
    }
  });
  // Interpolation reads only vectors settled above, so the order of nodes does not matter.
  std::vector<std::array<float, 3>> interpolated(n);
  std::vector<std::uint8_t> got(n, 0);
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n), [&](const auto& r) {
    for (std::size_t node = r.begin(); node < r.end(); ++node) {
      if (state[node] != 2) continue;
      got[node] = interpolate(
          f, c.count, node, [&](std::size_t m) { return f.valid[m] != 0; }, interpolated[node]);
    }
  });
  for (std::size_t node = 0; node < n; ++node) {
    if (state[node] == 0) continue;
    ++f.counts.outliers;
    if (state[node] == 1) {
      (c.flags[node] & flag_second_peak ? f.counts.second_peak : f.counts.third_peak)++;
    } else if (got[node]) {
      f.d[node] = interpolated[node];
      f.valid[node] = 1;
      c.flags[node] |= flag_interpolated;
      ++f.counts.interpolated;
    } else {
      c.flags[node] |= flag_unresolved;
      ++f.counts.unresolved;
    }
  }
  return f;
}

void revalidate_outliers(Candidates& c, const MedianTest& test, std::span<const std::size_t> nodes, ValidatedField& f) {
  constexpr std::uint8_t waiting = flag_interpolated | flag_unresolved;
  const int radius = std::clamp(test.radius, 1, max_radius);
  // Each node's secondary peaks against its neighbours' primaries, as validate tries them.
  std::vector<std::size_t> settled_now;
  Reference ref;
  for (const std::size_t node : nodes) {
    if (!(c.flags[node] & waiting))
      throw std::logic_error("revalidate_outliers: node " + std::to_string(node) + " is not an outlier left to its " +
                             "neighbours");
    gather_reference(c, node, radius, ref);
    find_medians(ref);
    const int rank = passing_secondary(c, node, ref, test);
    if (!rank) continue;
    (c.flags[node] & flag_interpolated ? f.counts.interpolated : f.counts.unresolved)--;
    (rank == 1 ? f.counts.second_peak : f.counts.third_peak)++;
    c.flags[node] = std::uint8_t((c.flags[node] & ~waiting) | secondary_flag(rank));
    f.d[node] = c.peak[rank][node];
    f.valid[node] = 1;
    settled_now.push_back(node);
  }
  // The outliers left to their neighbours within reach of a node settled now, interpolated again
  // from the settled vectors (those validate's interpolation reads: not interpolated themselves).
  std::vector<std::size_t> again;
  std::vector<std::uint8_t> marked(c.size(), 0);
  for (const std::size_t node : settled_now)
    for_neighbours(c.count, node, 2, [&](std::size_t m) {
      if ((c.flags[m] & waiting) && !marked[m]) {
        marked[m] = 1;
        again.push_back(m);
      }
    });
  const auto settled = [&](std::size_t m) { return f.valid[m] && !(c.flags[m] & flag_interpolated); };
  std::vector<std::array<float, 3>> interpolated(again.size());
  std::vector<std::uint8_t> got(again.size());
  for (std::size_t q = 0; q < again.size(); ++q) got[q] = interpolate(f, c.count, again[q], settled, interpolated[q]);
  for (std::size_t q = 0; q < again.size(); ++q) {
    const std::size_t node = again[q];
    if (!got[q]) continue;  // no settled neighbour before either: still unresolved
    if (c.flags[node] & flag_unresolved) {
      --f.counts.unresolved;
      ++f.counts.interpolated;
      c.flags[node] = std::uint8_t((c.flags[node] & ~flag_unresolved) | flag_interpolated);
    }
    f.d[node] = interpolated[q];
    f.valid[node] = 1;
  }
}

void smooth_valid(ValidatedField& f, std::array<int, 3> count, int passes) {
  const std::array<std::size_t, 3> stride{1, std::size_t(count[0]), std::size_t(count[0]) * count[1]};
  std::vector<std::array<float, 3>> in;
  for (int pass = 0; pass < passes; ++pass)
    for (int axis = 0; axis < 3; ++axis) {
      in = f.d;
      const std::size_t st = stride[axis];
      tbb::parallel_for(tbb::blocked_range<std::size_t>(0, in.size()), [&](const auto& r) {
        for (std::size_t node = r.begin(); node < r.end(); ++node) {
          const int c = int((node / st) % std::size_t(count[axis]));
          if (!f.valid[node] || c == 0 || c == count[axis] - 1 || !f.valid[node - st] || !f.valid[node + st]) continue;
          for (int a = 0; a < 3; ++a)
            f.d[node][a] = 0.25f * in[node - st][a] + 0.5f * in[node][a] + 0.25f * in[node + st][a];
        }
      });
    }
}

std::vector<std::array<float, 3>> fill_invalid(const ValidatedField& f, std::array<int, 3> count) {
  std::vector<std::array<float, 3>> out = f.d;
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, out.size()), [&](const auto& r) {
    for (std::size_t node = r.begin(); node < r.end(); ++node) {
      if (f.valid[node]) continue;
      if (!mean_of_valid(f, count, node, 2, out[node])) out[node] = {0, 0, 0};
    }
  });
  return out;
}

}  // namespace plenopiv::piv
