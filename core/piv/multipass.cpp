// Multi-pass, multigrid 3D cross-correlation with window deformation (VODIM, paper sec 6.3).
#include "core/piv/multipass.hpp"

#include <tbb/blocked_range.h>
#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_reduce.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstring>
#include <limits>
#include <optional>
#include <span>
#include <sstream>
#include <stdexcept>

#include "core/base/big_buffer.hpp"
#include "core/base/errors.hpp"
#include "core/base/isa.hpp"
#include "core/piv/deform.hpp"
#include "core/piv/direct_correlation.hpp"
#include "core/piv/fft_correlator.hpp"
#include "core/piv/peak_fit.hpp"
#include "core/piv/uncertainty.hpp"

namespace plenopiv::piv {
namespace {

using Clock = std::chrono::steady_clock;
double seconds_since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

std::string describe(const Grid3& g) {
  std::ostringstream s;
  s << g.shape[0] << "x" << g.shape[1] << "x" << g.shape[2] << " voxels, origin (" << g.origin_mm[0] << ", "
    << g.origin_mm[1] << ", " << g.origin_mm[2] << ") mm, spacing (" << g.spacing_mm[0] << ", " << g.spacing_mm[1]
    << ", " << g.spacing_mm[2] << ") mm";
  return s.str();
}

void check_inputs(const Volume& a, const Volume& b, const CorrelationSettings& s, int depth_context) {
  check(s, "correlation settings");
  if (depth_context < 0 || 2 * depth_context >= a.grid.shape[2])
    throw InputError("depth context: " + std::to_string(depth_context) + " slices at each depth end of a volume " +
                     std::to_string(a.grid.shape[2]) + " slices deep (0 to less than half of it)");
  if (!(a.grid == b.grid))
    throw InputError("the two volumes are on different grids: first " + describe(a.grid) + ", second " +
                     describe(b.grid));
  if (a.data.size() != a.grid.count() || b.data.size() != b.grid.count())
    throw InputError("volume data does not match its grid (" + describe(a.grid) + ")");
  for (const Volume* v : {&a, &b})
    for (float x : v->data)
      if (!std::isfinite(x))
        throw InputError(std::string(v == &a ? "first" : "second") +
                         " volume holds a non-finite intensity (NaN or infinity)");
  for (std::size_t p = 0; p < s.passes.size(); ++p)
    for (int axis = 0; axis < 3; ++axis) {
      const int room = a.grid.shape[axis] - (axis == 2 ? 2 * depth_context : 0);
      if (s.passes[p].window[axis] > room)
        throw InputError("passes[" + std::to_string(p) + "].window: " + std::to_string(s.passes[p].window[axis]) +
                         " voxels along " + "xyz"[axis] + " exceed the volume's " + std::to_string(room) +
                         (axis == 2 && depth_context ? " (its depth context left out)" : ""));
    }
}

// Windows of one pass: node i's window starts at voxel start[a] + i * step[a].
struct Layout {
  std::array<int, 3> window, step, start, count;
  int depth_margin = 0;  // PassSettings::depth_margin
  NodeField nodes() const {
    std::array<double, 3> first, st;
    for (int a = 0; a < 3; ++a) {
      first[a] = start[a] + 0.5 * (window[a] - 1);
      st[a] = step[a];
    }
    return NodeField(count, first, st);
  }
};

// The windows lie within the volume without its `depth_context` slices at each depth end.
Layout layout_of(const PassSettings& p, const std::array<int, 3>& shape, int depth_context) {
  Layout l;
  l.window = p.window;
  l.depth_margin = p.depth_margin;
  for (int a = 0; a < 3; ++a) {
    const int context = a == 2 ? depth_context : 0, length = shape[a] - 2 * context;
    l.step[a] = p.step(a);
    l.count[a] = (length - p.window[a]) / l.step[a] + 1;
    // Centre the set of windows in the volume.
    l.start[a] = context + (length - p.window[a] - (l.count[a] - 1) * l.step[a]) / 2;
  }
  return l;
}

typedef float Floats16 __attribute__((vector_size(64)));
typedef float Floats4 __attribute__((vector_size(16)));

// Copies `n` floats (or zeros, where `src` is null) and keeps their running maximum in `max16`,
// `max4` (lanes) and `max1` (the tail). The voxels are finite (checked), so the maximum does not
// depend on the order it is taken in.
[[gnu::always_inline]] inline void copy_row(const float* __restrict src, int n, float* __restrict dst, Floats16& max16,
                                            Floats4& max4, float& max1) {
  if (!src) {
    std::fill(dst, dst + n, 0.f);
    return;
  }
  int x = 0;
  for (; x + 16 <= n; x += 16) {
    Floats16 v;
    std::memcpy(&v, src + x, sizeof v);
    std::memcpy(dst + x, &v, sizeof v);
    max16 = max16 > v ? max16 : v;
  }
  for (; x + 4 <= n; x += 4) {
    Floats4 v;
    std::memcpy(&v, src + x, sizeof v);
    std::memcpy(dst + x, &v, sizeof v);
    max4 = max4 > v ? max4 : v;
  }
  for (; x < n; ++x) max1 = std::max(max1, dst[x] = src[x]);
}

// A window pair to copy: the window at `origin` (voxels) of volumes `va` and `vb` of `shape`,
// `margin` slices more of B at each depth end, into `wa` and `wb`.
struct WindowCopy {
  const float *va, *vb;
  const std::array<int, 3>& shape;
  std::array<int, 3> origin;
  const std::array<int, 3>& window;
  int margin;
  float *wa, *wb;
};

// The window of A (its slices in the middle, zeros in the margin slices at each depth end) and of B
// (all window[2] + 2 margin slices; zeros outside the volume), row by row; returns their brightest
// voxels. Built once per instruction set below: a 16-voxel row is one AVX-512 vector.
[[gnu::always_inline]] inline std::array<float, 2> copy_windows_body(const WindowCopy& j) {
  const float *va = j.va, *vb = j.vb;
  float *wa = j.wa, *wb = j.wb;
  const std::array<int, 3>& shape = j.shape;
  const std::array<int, 3>& origin = j.origin;
  const std::array<int, 3>& window = j.window;
  const int margin = j.margin;
  const Floats16 low16 = Floats16{} - INFINITY;
  const Floats4 low4 = Floats4{} - INFINITY;
  Floats16 max16_a = low16, max16_b = low16;
  Floats4 max4_a = low4, max4_b = low4;
  float max_a = -INFINITY, max_b = -INFINITY;
  const std::size_t plane = std::size_t(shape[0]) * shape[1];
  for (int z = -margin; z < window[2] + margin; ++z) {
    const int vz = origin[2] + z;
    const bool in_a = z >= 0 && z < window[2], in_volume = vz >= 0 && vz < shape[2];
    for (int y = 0; y < window[1]; ++y) {
      const std::size_t row =
          std::size_t(in_volume ? vz : 0) * plane + std::size_t(origin[1] + y) * shape[0] + origin[0];
      const std::size_t o = (std::size_t(z + margin) * window[1] + y) * window[0];
      copy_row(in_a ? va + row : nullptr, window[0], wa + o, max16_a, max4_a, max_a);
      copy_row(in_volume ? vb + row : nullptr, window[0], wb + o, max16_b, max4_b, max_b);
    }
  }
  for (int l = 0; l < 16; ++l) max_a = std::max(max_a, max16_a[l]), max_b = std::max(max_b, max16_b[l]);
  for (int l = 0; l < 4; ++l) max_a = std::max(max_a, max4_a[l]), max_b = std::max(max_b, max4_b[l]);
  return {max_a, max_b};
}

__attribute__((target("avx512f"))) std::array<float, 2> copy_windows_avx512(const WindowCopy& j) {
  return copy_windows_body(j);
}
__attribute__((target("avx2"))) std::array<float, 2> copy_windows_avx2(const WindowCopy& j) {
  return copy_windows_body(j);
}
std::array<float, 2> copy_windows_baseline(const WindowCopy& j) { return copy_windows_body(j); }
std::array<float, 2> copy_windows(const WindowCopy& j) {
  return for_isa(copy_windows_avx512, copy_windows_avx2, copy_windows_baseline)(j);
}

// With a depth margin (PassSettings::depth_margin): the cyclic correlation `corr` of window A (its
// `depth` slices in the middle of the buffer, zero-mean, zeros around) with the taller window B,
// divided at each depth shift s by the spread of B's intensity over the slices A covers at that
// shift, sqrt(sum (b - mean)^2); shifts beyond the margin are set to 0 (not searched). `slice_sum`
// and `slice_sum_sq` are B's per-slice sums of b and b^2.
void normalise_by_depth_shift(std::span<float> corr, std::size_t slice, int depth, int margin,
                              std::span<const double> slice_sum, std::span<const double> slice_sum_sq) {
  const int slices = depth + 2 * margin;
  const double count = double(slice) * depth;
  for (int kz = 0; kz < slices; ++kz) {
    const int shift = kz < slices / 2 ? kz : kz - slices;
    double scale = 0;
    if (std::abs(shift) <= margin) {
      double sum = 0, sum_sq = 0;
      for (int z = margin + shift; z < margin + shift + depth; ++z) sum += slice_sum[z], sum_sq += slice_sum_sq[z];
      const double spread = sum_sq - sum * sum / count;
      if (spread > 0) scale = 1.0 / std::sqrt(spread);
    }
    float* plane = corr.data() + std::size_t(kz) * slice;
    for (std::size_t q = 0; q < slice; ++q) plane[q] *= float(scale);
  }
}

// The sums of b and of b^2 over each slice of `slice` floats of `b` (sum and sum_sq: one per
// slice), each slice's in its voxels' order from 0, in double: four slices side by side, so that
// eight independent sums run at once rather than two that wait on each other (the same additions
// in the same order per slice).
void per_slice_sums(std::span<const float> b, std::size_t slice, std::span<double> sum, std::span<double> sum_sq) {
  const std::size_t slices = sum.size();
  for (std::size_t z0 = 0; z0 < slices; z0 += 4) {
    const std::size_t n = std::min<std::size_t>(4, slices - z0);
    double s[4] = {0, 0, 0, 0}, s2[4] = {0, 0, 0, 0};
    const float* rows[4];
    for (std::size_t k = 0; k < 4; ++k) rows[k] = b.data() + (z0 + std::min(k, n - 1)) * slice;
    for (std::size_t q = 0; q < slice; ++q)
      for (std::size_t k = 0; k < 4; ++k) {
        const double v = rows[k][q];
        s[k] += v;
        s2[k] += v * v;
      }
    for (std::size_t k = 0; k < n; ++k) {
      sum[z0 + k] = s[k];
      sum_sq[z0 + k] = s2[k];
    }
  }
}

// What a window of each volume must exceed somewhere to hold signal: the setting, or the volume's
// dust level (settings.hpp, kNumericalDust).
struct SignalBars {
  float a, b;
};
SignalBars signal_bars(std::span<const float> va, std::span<const float> vb, const CorrelationSettings& settings) {
  const auto bar = [&](std::span<const float> v) {
    const float peak = tbb::parallel_reduce(
        tbb::blocked_range<std::size_t>(0, v.size(), std::size_t(1) << 16), 0.f,
        [&](const tbb::blocked_range<std::size_t>& r, float m) {
          for (std::size_t i = r.begin(); i != r.end(); ++i) m = std::max(m, v[i]);
          return m;
        },
        [](float x, float y) { return std::max(x, y); });
    return std::max(settings.signal_threshold, kNumericalDust * peak);
  };
  return {bar(va), bar(vb)};
}

// Correlates every window of `va` with the same window of `vb` into `c` (made anew); a window's
// candidates are the predictor (at its centre, or its mean over the window: settings.hpp,
// PredictorBase) plus each correlation peak; `bases` gets that predictor per node (what each peak's
// shift was added to), `ratio` the peak ratio. The settings' spectral whitening applies unless this
// is the `last_pass`. With `near_predictor` (FinalPeakSearch; no depth margin, no whitening) a
// window whose correlation peaks at the predictor takes that peak alone (`near` set, ratio NaN);
// the others are correlated by FFT. With `only` non-empty just those nodes are correlated again, by
// FFT, in the `c`, `ratio`, `bases` and `near` of an earlier call. `bars`: signal_bars(va, vb).
void correlate_windows(std::span<const float> va, std::span<const float> vb, const std::array<int, 3>& shape,
                       const Layout& l, const NodeField* predictor, const CorrelationSettings& settings,
                       const SignalBars& bars, bool last_pass, bool near_predictor, std::span<const std::size_t> only,
                       Candidates& c, std::vector<float>& ratio, std::vector<std::array<float, 3>>& bases,
                       std::vector<std::uint8_t>& near) {
  const bool at_centre = settings.predictor == PredictorBase::centre;
  const int margin = l.depth_margin;
  const std::array<int, 3> fft_shape{l.window[0], l.window[1], l.window[2] + 2 * margin};
  const FftCorrelator& correlator = FftCorrelator::shared(fft_shape, settings.fft_planning);
  std::optional<SpectralWeights> weights;
  // CorrelationSettings::spectral_whitening: every pass but the last.
  if (settings.spectral_whitening > 0 && !last_pass)
    weights.emplace(fft_shape, settings.spectral_whitening, settings.whitened_peak_sigma_voxel);
  const SpectralWeights* spectral = weights ? &*weights : nullptr;
  const std::size_t slice = std::size_t(l.window[0]) * l.window[1];
  if (only.empty()) {
    c = Candidates(l.count);
    ratio.assign(c.size(), 0.f);
    bases.assign(c.size(), {0.f, 0.f, 0.f});
    near.assign(c.size(), 0);
  } else if (near_predictor) {
    throw std::logic_error("correlation: windows correlated again are searched over all shifts");
  }
  tbb::enumerable_thread_specific<std::vector<float>> star_scratch;
  // window_mean: the predictor's mean over each window, as per-axis node weights (the residual
  // a window measures is relative to how far its voxels were moved on average).
  std::array<std::vector<std::vector<double>>, 3> mean_weights;
  if (predictor && !at_centre)
    for (int a = 0; a < 3; ++a)
      for (int i = 0; i < l.count[a]; ++i)
        mean_weights[a].push_back(predictor->mean_weights(a, l.start[a] + i * l.step[a], l.window[a]));
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, only.empty() ? c.size() : only.size()), [&](const auto& r) {
    auto& ws = correlator.workspace();
    std::vector<double> slice_sums(margin ? 2 * std::size_t(fft_shape[2]) : 0);  // b, then b^2
    for (std::size_t item = r.begin(); item < r.end(); ++item) {
      const std::size_t node = only.empty() ? item : only[item];
      c.peaks[node] = 0;
      near[node] = 0;
      const int i = int(node % l.count[0]);
      const int j = int((node / l.count[0]) % l.count[1]);
      const int k = int(node / (std::size_t(l.count[0]) * l.count[1]));
      const int x0 = l.start[0] + i * l.step[0], y0 = l.start[1] + j * l.step[1], z0 = l.start[2] + k * l.step[2];
      auto wa = ws.window_a();
      auto wb = ws.window_b();
      // Slices -margin .. window + margin of B; A's are its window's, zeros in the margins.
      const auto [max_a, max_b] =
          copy_windows({va.data(), vb.data(), shape, {x0, y0, z0}, l.window, margin, wa.data(), wb.data()});
      if (!(max_a > bars.a && max_b > bars.b)) {
        c.flags[node] = flag_no_signal;
        continue;
      }
      std::array<Peak, 3> peaks{};
      if (near_predictor) {
        // The correlation at the predictor and its face neighbours (kStarShifts' order): the peak
        // where the centre is positive and beats all six (earlier neighbours at >=, later at >, as
        // find_peaks), fitted from the 3 x 3 x 3 cube fit_peak reads at shift 0 (faces only).
        const std::size_t count = slice * l.window[2];
        const auto star = correlate_star(wa.first(count), wb.first(count), l.window, star_scratch.local());
        const bool peak = star[0] > 0 && star[1] < star[0] && star[2] <= star[0] && star[3] < star[0] &&
                          star[4] <= star[0] && star[5] < star[0] && star[6] <= star[0];
        if (peak) {
          // Cyclic 3 x 3 x 3 ([z][y][x], shift -1 at index 2); the diagonals are not read.
          std::array<float, 27> cube{};
          cube[0] = star[0];
          cube[2] = star[1];
          cube[1] = star[2];
          cube[2 * 3] = star[3];
          cube[1 * 3] = star[4];
          cube[2 * 9] = star[5];
          cube[1 * 9] = star[6];
          peaks[0] = fit_peak(cube, {3, 3, 3}, {0, 0, 0});
          near[node] = 1;
        }
      }
      if (!near[node]) {
        std::span<float> corr;
        if (margin == 0) {
          corr = ws.correlate(spectral);  // the transform takes out both windows' means
        } else {
          // A's mean over its own voxels, not the padded buffer's; B's sums per slice for the
          // normalisation, taken before correlate() consumes the window.
          float* a_window = wa.data() + std::size_t(margin) * slice;
          const std::size_t a_count = slice * l.window[2];
          double sum_a = 0;
          for (std::size_t q = 0; q < a_count; ++q) sum_a += a_window[q];
          const float mean_a = float(sum_a / double(a_count));
          for (std::size_t q = 0; q < a_count; ++q) a_window[q] -= mean_a;
          const std::size_t slices = std::size_t(fft_shape[2]);
          const std::span<double> sums(slice_sums);
          per_slice_sums(wb.first(slices * slice), slice, sums.first(slices), sums.subspan(slices));
          corr = ws.correlate(spectral);
          normalise_by_depth_shift(corr, slice, l.window[2], margin, sums.first(slices), sums.subspan(slices));
        }
        peaks = find_peaks(corr, fft_shape);
      }
      std::array<float, 3> base{0, 0, 0};
      if (predictor && at_centre) {
        base = predictor->at(x0 + 0.5 * (l.window[0] - 1), y0 + 0.5 * (l.window[1] - 1), z0 + 0.5 * (l.window[2] - 1));
      } else if (predictor) {
        const auto& wx = mean_weights[0][i];
        const auto& wy = mean_weights[1][j];
        const auto& wz = mean_weights[2][k];
        double sum[3] = {0, 0, 0};
        for (int pk = 0; pk < predictor->count[2]; ++pk) {
          if (wz[pk] == 0) continue;
          for (int pj = 0; pj < predictor->count[1]; ++pj) {
            if (wy[pj] == 0) continue;
            for (int pi = 0; pi < predictor->count[0]; ++pi) {
              if (wx[pi] == 0) continue;
              const double w = wx[pi] * wy[pj] * wz[pk];
              const std::size_t m = predictor->index(pi, pj, pk);
              for (int a = 0; a < 3; ++a) sum[a] += w * predictor->d[a][m];
            }
          }
        }
        for (int a = 0; a < 3; ++a) base[a] = float(sum[a]);
      }
      bases[node] = base;
      int found = 0;
      for (const Peak& p : peaks) {
        if (!(p.value > 0)) break;
        for (int a = 0; a < 3; ++a) c.peak[found][node][a] = base[a] + p.shift[a];
        ++found;
      }
      if (!found) {
        c.flags[node] = flag_no_signal;
        continue;
      }
      c.peaks[node] = std::uint8_t(found);
      c.flags[node] = peaks[0].flags;
      ratio[node] = near[node] ? std::numeric_limits<float>::quiet_NaN() : peak_ratio(peaks);
    }
  });
}

// The standard uncertainty (voxels) of every vector the final pass measured (valid and not
// replaced by its neighbours' mean; NaN elsewhere), from the windows it correlated, `va` and
// `vb`: per axis x, y, z, one value per node. The peak behind a vector is at the integer shift
// nearest its displacement less the predictor it was added to (`bases`). With `stride` > 1 the
// nodes between those computed are interpolated where they can be (CorrelationSettings::
// uncertainty_stride says where).
std::array<std::vector<float>, 3> vector_uncertainty(std::span<const float> va, std::span<const float> vb,
                                                     const std::array<int, 3>& shape, const Layout& l,
                                                     const ValidatedField& f, std::span<const std::uint8_t> flags,
                                                     const std::vector<std::array<float, 3>>& bases, int stride) {
  std::array<std::vector<float>, 3> sigma;
  for (auto& s : sigma) s.assign(f.d.size(), std::numeric_limits<float>::quiet_NaN());
  const std::size_t nx = std::size_t(l.count[0]), nxy = nx * std::size_t(l.count[1]);
  const std::array<std::size_t, 3> node_stride{1, nx, nxy};
  const auto index = [&](std::size_t node) {
    return std::array<int, 3>{int(node % nx), int((node / nx) % std::size_t(l.count[1])), int(node / nxy)};
  };
  const auto shift_of = [&](std::size_t node) {
    std::array<int, 3> shift;
    for (int a = 0; a < 3; ++a) shift[a] = int(std::lround(f.d[node][a] - bases[node][a]));
    return shift;
  };
  const auto measured = [&](std::size_t node) { return f.valid[node] && !(flags[node] & flag_interpolated); };
  // Along an axis, index i lies between the computed indices lo and hi (lo == hi: i is one).
  const auto computed_along = [&](int i, int axis) { return i % stride == 0 || i == l.count[axis] - 1; };
  const auto bracket = [&](int i, int axis) {
    const int lo = i - i % stride;
    return computed_along(i, axis) ? std::array<int, 2>{i, i}
                                   : std::array<int, 2>{lo, std::min(lo + stride, l.count[axis] - 1)};
  };
  const auto computed = [&](const std::array<int, 3>& ijk) {
    return computed_along(ijk[0], 0) && computed_along(ijk[1], 1) && computed_along(ijk[2], 2);
  };
  tbb::enumerable_thread_specific<UncertaintyScratch> scratch;
  const auto compute = [&](std::size_t node, const std::array<int, 3>& ijk, UncertaintyScratch& s) {
    const auto v = correlation_statistics_sigma(
        va, vb, shape,
        {l.start[0] + ijk[0] * l.step[0], l.start[1] + ijk[1] * l.step[1], l.start[2] + ijk[2] * l.step[2]}, l.window,
        l.depth_margin, shift_of(node), s);
    for (int a = 0; a < 3; ++a) sigma[a][node] = v[a];
  };
  // First the computed nodes, then the rest: interpolated from the eight (or fewer, on a computed
  // index) bracketing nodes when each has all three estimates from a peak at this node's shift.
  for (const bool first : {true, false}) {
    if (!first && stride == 1) break;
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, f.d.size()), [&](const auto& r) {
      UncertaintyScratch& s = scratch.local();
      for (std::size_t node = r.begin(); node < r.end(); ++node) {
        if (!measured(node)) continue;
        const std::array<int, 3> ijk = index(node);
        if (computed(ijk) != first) continue;
        if (first) {
          compute(node, ijk, s);
          continue;
        }
        // Per axis the bracketing indices and the fraction of the way from the first to the second.
        std::array<std::array<int, 2>, 3> b;
        std::array<double, 3> t;
        for (int a = 0; a < 3; ++a) {
          b[a] = bracket(ijk[a], a);
          t[a] = b[a][1] == b[a][0] ? 0.5 : double(ijk[a] - b[a][0]) / (b[a][1] - b[a][0]);
        }
        const std::array<int, 3> shift = shift_of(node);
        std::array<double, 3> sum{0, 0, 0};
        bool whole = true;
        for (int c = 0; c < 8 && whole; ++c) {
          double w = 1;
          std::size_t at = 0;
          for (int a = 0; a < 3; ++a) {
            const int high = (c >> a) & 1;
            w *= high ? t[a] : 1 - t[a];
            at += std::size_t(b[a][high]) * node_stride[a];
          }
          whole = shift_of(at) == shift;
          for (int a = 0; a < 3 && whole; ++a) {
            whole = std::isfinite(sigma[a][at]);
            sum[a] += w * sigma[a][at];
          }
        }
        if (!whole) {
          compute(node, ijk, s);
          continue;
        }
        for (int a = 0; a < 3; ++a) sigma[a][node] = float(sum[a]);
      }
    });
  }
  return sigma;
}

}  // namespace

struct CorrelationWorkspace::Buffers {
  std::atomic<bool> busy{false};
  BigBuffer<float> smoothed_a, smoothed_b, deformed_a, deformed_b;
};

CorrelationWorkspace::CorrelationWorkspace() : buffers_(std::make_unique<Buffers>()) {}
CorrelationWorkspace::~CorrelationWorkspace() = default;
CorrelationWorkspace::CorrelationWorkspace(CorrelationWorkspace&&) noexcept = default;
CorrelationWorkspace& CorrelationWorkspace::operator=(CorrelationWorkspace&&) noexcept = default;

std::size_t CorrelationWorkspace::bytes() const {
  if (!buffers_) return 0;  // moved from
  const Buffers& b = *buffers_;
  return (b.smoothed_a.capacity() + b.smoothed_b.capacity() + b.deformed_a.capacity() + b.deformed_b.capacity()) *
         sizeof(float);
}

void CorrelationWorkspace::reserve(std::size_t voxels) {
  if (!buffers_) throw std::logic_error("correlation: the workspace was moved from");
  Buffers& b = *buffers_;
  if (b.busy.exchange(true)) throw std::logic_error("correlation: the workspace is in use by a correlation");
  struct Release {
    std::atomic<bool>& busy;
    ~Release() { busy.store(false); }
  } release{b.busy};
  for (BigBuffer<float>* v : {&b.smoothed_a, &b.smoothed_b, &b.deformed_a, &b.deformed_b}) v->assign(voxels, 0.f);
}

CorrelationResult correlate_volumes(const Volume& a, const Volume& b, const CorrelationSettings& settings,
                                    const std::function<void(const PassReport&)>& on_pass, int depth_context,
                                    CorrelationWorkspace* workspace) {
  check_inputs(a, b, settings, depth_context);
  const std::array<int, 3> shape = a.grid.shape;
  // Volume-sized copies (four volumes), neither zeroed nor carried between calls: each is written
  // in full before it is read. The caller's, or this call's.
  CorrelationWorkspace local;
  CorrelationWorkspace& ws = workspace ? *workspace : local;
  if (!ws.buffers_) throw std::logic_error("correlation: the workspace was moved from");
  CorrelationWorkspace::Buffers& buffers = *ws.buffers_;
  if (buffers.busy.exchange(true))
    throw std::logic_error("correlation: the workspace is in use by another correlation; give each its own");
  struct Release {
    std::atomic<bool>& busy;
    ~Release() { busy.store(false); }
  } release{buffers.busy};
  BigBuffer<float>& smoothed_a = buffers.smoothed_a;
  BigBuffer<float>& smoothed_b = buffers.smoothed_b;
  BigBuffer<float>& deformed_a = buffers.deformed_a;
  BigBuffer<float>& deformed_b = buffers.deformed_b;
  std::span<const float> input_a = a.data, input_b = b.data;
  if (settings.intensity_threshold_of_mean > 0) {
    // Floored copies, in the deformed buffers (unused until pass 2) when the prefilter follows.
    BigBuffer<float>& floored_a = settings.prefilter ? deformed_a : smoothed_a;
    BigBuffer<float>& floored_b = settings.prefilter ? deformed_b : smoothed_b;
    floored_a.resize(a.data.size());
    floored_b.resize(b.data.size());
    subtract_mean_floor(a.data, shape, settings.intensity_threshold_of_mean, floored_a);
    subtract_mean_floor(b.data, shape, settings.intensity_threshold_of_mean, floored_b);
    input_a = floored_a;
    input_b = floored_b;
  }
  if (settings.prefilter) {
    smoothed_a.resize(a.data.size());
    smoothed_b.resize(b.data.size());
    deformed_a.resize(a.data.size());
    // The smoothing needs one scratch volume: smoothed_b while A is smoothed, then deformed_a
    // (A's floored copy, if any, is read by then).
    binomial_smooth(input_a, shape, smoothed_a, smoothed_b, settings.depth_prefilter);
    binomial_smooth(input_b, shape, smoothed_b, deformed_a, settings.depth_prefilter);
    input_a = smoothed_a;
    input_b = smoothed_b;
  }
  NodeField predictor;
  bool have_predictor = false;
  CorrelationResult result;
  Candidates last;
  ValidatedField validated;
  std::vector<float> ratio;
  std::vector<std::array<float, 3>> bases;
  std::vector<std::uint8_t> near;           // per node: peak found at the predictor (FinalPeakSearch)
  std::array<std::vector<float>, 3> sigma;  // voxels, x y z; empty unless settings.uncertainty
  Layout layout{};
  const int passes = int(settings.passes.size());
  for (int p = 0; p < passes; ++p) {
    PassReport report;
    report.pass = p + 1;
    report.passes = passes;
    report.settings = settings.passes[p];
    layout = layout_of(settings.passes[p], shape, depth_context);
    report.vectors = layout.count;

    auto t0 = Clock::now();
    std::span<const float> va = input_a, vb = input_b;
    if (have_predictor) {
      deformed_a.resize(a.data.size());
      deformed_b.resize(b.data.size());
      deform_pair(input_a, input_b, shape, predictor, deformed_a, deformed_b,
                  p + 1 == passes ? Interpolation::sinc : settings.early_interpolation);
      va = deformed_a;
      vb = deformed_b;
    }
    report.deform_s = seconds_since(t0);

    t0 = Clock::now();
    const NodeField* pass_predictor = have_predictor ? &predictor : nullptr;
    const bool near_predictor = p + 1 == passes && settings.final_peak_search == FinalPeakSearch::near_predictor;
    const SignalBars bars = signal_bars(va, vb, settings);
    correlate_windows(va, vb, shape, layout, pass_predictor, settings, bars, p + 1 == passes, near_predictor, {}, last,
                      ratio, bases, near);
    report.correlate_s = seconds_since(t0);
    report.windows = last.size();
    for (std::size_t n = 0; n < last.size(); ++n) {
      report.no_signal += (last.flags[n] & flag_no_signal) != 0;
      report.flag_parabolic += (last.flags[n] & flag_parabolic) != 0;
      report.flag_centroid += (last.flags[n] & flag_centroid) != 0;
    }

    t0 = Clock::now();
    validated = validate(last, settings.median);
    if (near_predictor) {
      // A peak found at the predictor stays its vector's primary; where the test rejects it, the
      // window is correlated over all shifts and the transform's two highest other peaks become
      // its second and third (the validation's replacements). No primary changes, so no other
      // vector's test does: only the replacements are tried, and interpolation redone near them.
      constexpr std::uint8_t waiting = flag_interpolated | flag_unresolved;
      std::vector<std::size_t> again;
      for (std::size_t n = 0; n < last.size(); ++n)
        if (near[n] && (last.flags[n] & waiting)) again.push_back(n);
      if (!again.empty()) {
        std::vector<std::array<float, 3>> found(again.size());
        std::vector<std::uint8_t> found_flags(again.size());
        for (std::size_t q = 0; q < again.size(); ++q) {
          found[q] = last.peak[0][again[q]];
          found_flags[q] = last.flags[again[q]];
        }
        const auto t_again = Clock::now();
        correlate_windows(va, vb, shape, layout, pass_predictor, settings, bars, true, false, again, last, ratio, bases,
                          near);
        report.correlate_s += seconds_since(t_again);
        for (std::size_t q = 0; q < again.size(); ++q) {
          const std::size_t n = again[q];
          std::array<std::array<float, 3>, 3> peaks{found[q]};
          int count = 1;
          for (int rank = 0; rank < last.peaks[n] && count < 3; ++rank) {
            bool same = true;  // the peak found at the predictor (a fit within half a voxel of it)
            for (int a = 0; a < 3; ++a) same = same && std::abs(last.peak[rank][n][a] - found[q][a]) < 0.5f;
            if (!same) peaks[std::size_t(count++)] = last.peak[rank][n];
          }
          for (int rank = 0; rank < count; ++rank) last.peak[rank][n] = peaks[std::size_t(rank)];
          last.peaks[n] = std::uint8_t(count);
          last.flags[n] = found_flags[q];
        }
        revalidate_outliers(last, settings.median, again, validated);
        report.near_rejected = again.size();
      }
      report.near_peaks = std::size_t(std::count(near.begin(), near.end(), 1));
    }
    report.validation = validated.counts;
    if (p + 1 == passes && settings.uncertainty) {
      const auto t_sigma = Clock::now();
      sigma = vector_uncertainty(va, vb, shape, layout, validated, last.flags, bases, settings.uncertainty_stride);
      report.uncertainty_s = seconds_since(t_sigma);
    }
    if (p + 1 < passes) {
      predictor = layout.nodes();
      const auto filled = fill_invalid(validated, layout.count);
      for (std::size_t n = 0; n < filled.size(); ++n)
        for (int c = 0; c < 3; ++c) predictor.d[c][n] = filled[n][c];
      // Smoothing between passes: settings.hpp (PredictorBase) says why.
      std::vector<float> smoothed(predictor.size()), scratch(predictor.size());
      for (int c = 0; c < 3; ++c)
        for (int it = 0; it < settings.predictor_smoothing; ++it) {
          binomial_smooth(predictor.d[c], layout.count, smoothed, scratch);
          predictor.d[c].swap(smoothed);
        }
      have_predictor = true;
    }
    report.validate_s = seconds_since(t0);
    result.passes.push_back(report);
    if (on_pass) on_pass(report);
  }

  if (settings.final_smoothing > 0) {
    smooth_valid(validated, layout.count, settings.final_smoothing);
    if (settings.uncertainty)
      for (auto& s : sigma)
        smooth_sigma(s, validated.valid, layout.count, settings.final_smoothing, layout.step, layout.window);
  }

  Grid3 g;
  g.shape = layout.count;
  const NodeField nodes = layout.nodes();
  for (int axis = 0; axis < 3; ++axis) {
    g.origin_mm[axis] = a.grid.origin_mm[axis] + nodes.first[axis] * a.grid.spacing_mm[axis];
    g.spacing_mm[axis] = nodes.step[axis] * a.grid.spacing_mm[axis];
  }
  VectorField& f = result.field;
  f = VectorField(g);
  f.dt_s = settings.dt_s;
  if (settings.uncertainty) {
    f.sigma_method = correlation_statistics_method(settings.uncertainty_stride, settings.final_smoothing);
    const std::array<std::vector<float>*, 3> out{&f.sigma_dx_mm, &f.sigma_dy_mm, &f.sigma_dz_mm};
    for (int axis = 0; axis < 3; ++axis) {
      out[axis]->resize(g.count());
      for (std::size_t n = 0; n < g.count(); ++n)
        (*out[axis])[n] = validated.valid[n] ? float(sigma[axis][n] * a.grid.spacing_mm[axis])
                                             : std::numeric_limits<float>::quiet_NaN();
    }
  }
  for (std::size_t n = 0; n < g.count(); ++n) {
    f.valid[n] = validated.valid[n];
    f.peak_ratio[n] = ratio[n];
    if (!f.valid[n]) continue;
    f.dx_mm[n] = float(validated.d[n][0] * a.grid.spacing_mm[0]);
    f.dy_mm[n] = float(validated.d[n][1] * a.grid.spacing_mm[1]);
    f.dz_mm[n] = float(validated.d[n][2] * a.grid.spacing_mm[2]);
  }
  result.flags = last.flags;
  return result;
}

}  // namespace plenopiv::piv
