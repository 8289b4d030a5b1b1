// Multi-pass, multigrid 3D cross-correlation with window deformation (VODIM, paper sec 6.3).
#include "core/piv/multipass.hpp"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <xmmintrin.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <span>
#include <sstream>

#include "core/base/big_buffer.hpp"
#include "core/base/errors.hpp"
#include "core/piv/deform.hpp"
#include "core/piv/fft_correlator.hpp"
#include "core/piv/peak_fit.hpp"

namespace plenopiv::piv {
namespace {

using Clock = std::chrono::steady_clock;
double seconds_since(Clock::time_point t0) {
  return std::chrono::duration<double>(Clock::now() - t0).count();
}

std::string describe(const Grid3& g) {
  std::ostringstream s;
  s << g.shape[0] << "x" << g.shape[1] << "x" << g.shape[2] << " voxels, origin (" << g.origin_mm[0]
    << ", " << g.origin_mm[1] << ", " << g.origin_mm[2] << ") mm, spacing (" << g.spacing_mm[0]
    << ", " << g.spacing_mm[1] << ", " << g.spacing_mm[2] << ") mm";
  return s.str();
}

void check_inputs(const Volume& a, const Volume& b, const CorrelationSettings& s) {
  check(s, "correlation settings");
  if (!(a.grid == b.grid))
    throw InputError("the two volumes are on different grids: first " + describe(a.grid) +
                     ", second " + describe(b.grid));
  if (a.data.size() != a.grid.count() || b.data.size() != b.grid.count())
    throw InputError("volume data does not match its grid (" + describe(a.grid) + ")");
  for (const Volume* v : {&a, &b})
    for (float x : v->data)
      if (!std::isfinite(x))
        throw InputError(std::string(v == &a ? "first" : "second") +
                         " volume holds a non-finite intensity (NaN or infinity)");
  for (std::size_t p = 0; p < s.passes.size(); ++p)
    for (int axis = 0; axis < 3; ++axis)
      if (s.passes[p].window[axis] > a.grid.shape[axis])
        throw InputError("passes[" + std::to_string(p) + "].window: " +
                         std::to_string(s.passes[p].window[axis]) + " voxels along " +
                         "xyz"[axis] + " exceed the volume's " +
                         std::to_string(a.grid.shape[axis]));
}

// Windows of one pass: node i's window starts at voxel start[a] + i * step[a].
struct Layout {
  std::array<int, 3> window, step, start, count;
  NodeField nodes() const {
    std::array<double, 3> first, st;
    for (int a = 0; a < 3; ++a) {
      first[a] = start[a] + 0.5 * (window[a] - 1);
      st[a] = step[a];
    }
    return NodeField(count, first, st);
  }
};

Layout layout_of(const PassSettings& p, const std::array<int, 3>& shape) {
  Layout l;
  l.window = p.window;
  for (int a = 0; a < 3; ++a) {
    l.step[a] = std::max(1, int(std::lround(p.window[a] * (1 - p.overlap_percent / 100))));
    l.count[a] = (shape[a] - p.window[a]) / l.step[a] + 1;
    // Centre the set of windows in the volume.
    l.start[a] = (shape[a] - p.window[a] - (l.count[a] - 1) * l.step[a]) / 2;
  }
  return l;
}

// Correlates every window of `va` with the same window of `vb`; a window's candidates are the
// predictor (at its centre, or its mean over the window: settings.hpp, PredictorBase) plus each
// correlation peak.
Candidates correlate_windows(std::span<const float> va, std::span<const float> vb,
                             const std::array<int, 3>& shape, const Layout& l,
                             const NodeField* predictor, float signal_threshold,
                             FftPlanning planning, bool at_centre, std::vector<float>& ratio) {
  const FftCorrelator& correlator = FftCorrelator::shared(l.window, planning);
  Candidates c(l.count);
  // window_mean: the predictor's mean over each window, as per-axis node weights (the residual
  // a window measures is relative to how far its voxels were moved on average).
  std::array<std::vector<std::vector<double>>, 3> mean_weights;
  if (predictor && !at_centre)
    for (int a = 0; a < 3; ++a)
      for (int i = 0; i < l.count[a]; ++i)
        mean_weights[a].push_back(predictor->mean_weights(a, l.start[a] + i * l.step[a], l.window[a]));
  ratio.assign(c.size(), 0.f);
  const std::size_t plane = std::size_t(shape[0]) * shape[1];
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, c.size()), [&](const auto& r) {
    auto& ws = correlator.workspace();
    for (std::size_t node = r.begin(); node < r.end(); ++node) {
      const int i = int(node % l.count[0]);
      const int j = int((node / l.count[0]) % l.count[1]);
      const int k = int(node / (std::size_t(l.count[0]) * l.count[1]));
      const int x0 = l.start[0] + i * l.step[0], y0 = l.start[1] + j * l.step[1],
                z0 = l.start[2] + k * l.step[2];
      auto wa = ws.window_a();
      auto wb = ws.window_b();
      // Copy the window and take its largest value four voxels at a time (SSE). The voxels are
      // finite (checked), so the maximum does not depend on the order it is taken in.
      __m128 max4_a = _mm_set1_ps(-INFINITY), max4_b = max4_a;
      float max_a = -INFINITY, max_b = -INFINITY;
      std::size_t o = 0;
      for (int z = 0; z < l.window[2]; ++z)
        for (int y = 0; y < l.window[1]; ++y) {
          const std::size_t row = (z0 + z) * plane + std::size_t(y0 + y) * shape[0] + x0;
          int x = 0;
          for (; x + 4 <= l.window[0]; x += 4, o += 4) {
            const __m128 qa = _mm_loadu_ps(&va[row + x]), qb = _mm_loadu_ps(&vb[row + x]);
            _mm_storeu_ps(&wa[o], qa);
            _mm_storeu_ps(&wb[o], qb);
            max4_a = _mm_max_ps(max4_a, qa);
            max4_b = _mm_max_ps(max4_b, qb);
          }
          for (; x < l.window[0]; ++x, ++o) {
            wa[o] = va[row + x];
            wb[o] = vb[row + x];
            max_a = std::max(max_a, wa[o]);
            max_b = std::max(max_b, wb[o]);
          }
        }
      float lanes_a[4], lanes_b[4];
      _mm_storeu_ps(lanes_a, max4_a);
      _mm_storeu_ps(lanes_b, max4_b);
      for (int k = 0; k < 4; ++k) {
        max_a = std::max(max_a, lanes_a[k]);
        max_b = std::max(max_b, lanes_b[k]);
      }
      if (!(max_a > signal_threshold && max_b > signal_threshold)) {
        c.flags[node] = flag_no_signal;
        continue;
      }
      const auto peaks = find_peaks(ws.correlate(), l.window);
      std::array<float, 3> base{0, 0, 0};
      if (predictor && at_centre) {
        base = predictor->at(x0 + 0.5 * (l.window[0] - 1), y0 + 0.5 * (l.window[1] - 1),
                             z0 + 0.5 * (l.window[2] - 1));
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
      ratio[node] = peak_ratio(peaks);
    }
  });
  return c;
}

}  // namespace

CorrelationResult correlate_volumes(const Volume& a, const Volume& b,
                                    const CorrelationSettings& settings,
                                    const std::function<void(const PassReport&)>& on_pass) {
  check_inputs(a, b, settings);
  const std::array<int, 3> shape = a.grid.shape;
  // Volume-sized copies (4 x 48 MB on the paper's grid), neither zeroed nor kept: each is written
  // in full before it is read.
  BigBuffer<float> smoothed_a, smoothed_b, deformed_a, deformed_b;
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
    binomial_smooth(input_a, shape, smoothed_a, smoothed_b);
    binomial_smooth(input_b, shape, smoothed_b, deformed_a);
    input_a = smoothed_a;
    input_b = smoothed_b;
  }
  NodeField predictor;
  bool have_predictor = false;
  CorrelationResult result;
  Candidates last;
  ValidatedField validated;
  std::vector<float> ratio;
  Layout layout{};
  const int passes = int(settings.passes.size());
  for (int p = 0; p < passes; ++p) {
    PassReport report;
    report.pass = p + 1;
    report.passes = passes;
    report.settings = settings.passes[p];
    layout = layout_of(settings.passes[p], shape);
    report.vectors = layout.count;

    auto t0 = Clock::now();
    std::span<const float> va = input_a, vb = input_b;
    if (have_predictor) {
      deformed_a.resize(a.data.size());
      deformed_b.resize(b.data.size());
      deform_pair(input_a, input_b, shape, predictor, deformed_a, deformed_b);
      va = deformed_a;
      vb = deformed_b;
    }
    report.deform_s = seconds_since(t0);

    t0 = Clock::now();
    last = correlate_windows(va, vb, shape, layout, have_predictor ? &predictor : nullptr,
                             settings.signal_threshold, settings.fft_planning,
                             settings.predictor == PredictorBase::centre, ratio);
    report.correlate_s = seconds_since(t0);
    report.windows = last.size();
    for (std::size_t n = 0; n < last.size(); ++n) {
      report.no_signal += (last.flags[n] & flag_no_signal) != 0;
      report.flag_parabolic += (last.flags[n] & flag_parabolic) != 0;
      report.flag_centroid += (last.flags[n] & flag_centroid) != 0;
    }

    t0 = Clock::now();
    validated = validate(last, settings.median);
    report.validation = validated.counts;
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
