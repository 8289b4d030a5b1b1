// Correlation benchmark (paper sec 6.3-6.4): sub-voxel accuracy on exact-particle volumes,
// the ring vortex at 300x200x200 (RMS per component), and the time of that correlation.
//
//   build/bin/bench_piv [--quick]
//   build/bin/bench_piv --default   (only the full-scale ring with the default, 2 threads and 1: for timing)
//   build/bin/bench_piv --decompose [default|<c|m><smoothing>:<passes> ...]   (where the ring error sits)
//
// Prints one machine-readable line per figure (key=value); docs/benchmarks.md records them.
#include <sys/resource.h>
#include <tbb/blocked_range.h>
#include <tbb/global_control.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <functional>
#include <string>

#include "bench/bench_support.hpp"
#include "core/piv/fft_correlator.hpp"
#include "core/piv/multipass.hpp"
#include "core/sim/exact_volume.hpp"
#include "core/sim/field_errors.hpp"
#include "core/sim/flows.hpp"
#include "core/sim/particles.hpp"

using namespace plenopiv;

namespace {

constexpr double voxel_mm = 0.1;

Grid3 centred_grid(int nx, int ny, int nz) {
  Grid3 g;
  g.shape = {nx, ny, nz};
  g.spacing_mm = {voxel_mm, voxel_mm, voxel_mm};
  for (int a = 0; a < 3; ++a) g.origin_mm[a] = -0.5 * (g.shape[a] - 1) * voxel_mm;
  return g;
}

double cpu_seconds() {
  rusage u{};
  getrusage(RUSAGE_SELF, &u);
  return u.ru_utime.tv_sec + 1e-6 * u.ru_utime.tv_usec + u.ru_stime.tv_sec + 1e-6 * u.ru_stime.tv_usec;
}

// Wall and CPU seconds of f. On a shared machine the CPU time is the steadier figure.
std::pair<double, double> seconds_of(const std::function<void()>& f) {
  const double c0 = cpu_seconds();
  const auto t0 = std::chrono::steady_clock::now();
  f();
  return {std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count(), cpu_seconds() - c0};
}

void uniform_shifts(int n) {
  const Grid3 g = centred_grid(n, n, n);
  const auto pa = sim::particles_around(g, 1);
  const Volume a = sim::render_exact_volume(g, pa);
  for (bool prefilter : {true, false})
    for (int step = 0; step <= 10; ++step) {
      piv::CorrelationSettings settings;  // the default three passes
      settings.prefilter = prefilter;
      const double t = 0.1 * step;
      const sim::UniformFlow flow({t * voxel_mm, t * voxel_mm, t * voxel_mm});
      const Volume b = sim::render_exact_volume(g, sim::displace(pa, flow));
      const auto r = piv::correlate_volumes(a, b, settings);
      for (int skip : {0, 1}) {
        // skip: vector-grid layers left out at every face.
        const sim::FieldErrors s = sim::field_errors(r.field, flow, voxel_mm, 1, skip);
        std::printf(
            "bench=piv_uniform volume=%d^3 prefilter=%d shift_voxel=%.1f vectors=%s n=%zu "
            "bias_x=%.4f bias_y=%.4f bias_z=%.4f rms_x=%.4f rms_y=%.4f rms_z=%.4f\n",
            n, int(prefilter), t, skip ? "interior" : "all", s.compared, s.bias[0], s.bias[1], s.bias[2], s.rms[0],
            s.rms[1], s.rms[2]);
      }
    }
}

// `all_variants`: also the slower pass schedules and FFTW_MEASURE (quick mode only: at full
// scale each costs a minute of the shared machine). `default_only`: just the default's two rows.
void ring_vortex(const std::array<int, 3>& shape, bool all_variants, bool default_only = false) {
  const Grid3 g = centred_grid(shape[0], shape[1], shape[2]);
  const sim::RingVortexFlow flow(sim::RingVortexFlow::Parameters{});  // the paper's ring
  const auto pa = sim::particles_around(g, 2);
  const Volume a = sim::render_exact_volume(g, pa);
  const Volume b = sim::render_exact_volume(g, sim::displace(pa, flow));
  struct Variant {
    std::string name;
    std::vector<piv::PassSettings> passes;
    int threads;
    piv::FftPlanning planning = piv::FftPlanning::estimate;
    bool always = false;
    bool prefilter = true;
    piv::PredictorBase predictor = piv::PredictorBase::centre;
    int smoothing = 1;
    piv::Interpolation early = piv::Interpolation::sinc;
  };
  using P = piv::PassSettings;
  const std::vector<P> three{{{32, 32, 32}, 50}, {{16, 16, 16}, 50}, {{16, 16, 16}, 75}};
  auto with = [](std::vector<P> p, const P& extra) {
    p.insert(p.end() - 1, extra);
    return p;
  };
  const auto mean = piv::PredictorBase::window_mean;
  const std::vector<Variant> variants{
      {"default_4pass_2threads", piv::CorrelationSettings{}.passes, 2, {}, true},
      {"default_4pass_1thread", piv::CorrelationSettings{}.passes, 1, {}, true},
      // The passes before the last deformed with Keys' cubic instead of the sinc.
      {"default_4pass_early_cubic",
       piv::CorrelationSettings{}.passes,
       2,
       {},
       true,
       true,
       piv::PredictorBase::centre,
       1,
       piv::Interpolation::cubic},
      // Three passes, residual added to the predictor's window mean, unsmoothed: the schedule the
      // centre predictor, its smoothing and the fourth pass are compared against.
      {"previous_default_3pass_window_mean", three, 2, {}, true, true, mean, 0},
      {"centre_3pass", three, 2, {}, true},
      {"centre_4pass_16_75", with(three, {{16, 16, 16}, 75}), 2, {}, true},
      {"default_fftw_measure", piv::CorrelationSettings{}.passes, 2, piv::FftPlanning::measure},
      {"default_no_prefilter", piv::CorrelationSettings{}.passes, 2, {}, true, false},
      {"single_pass_16", {{{16, 16, 16}, 75}}, 2, {}, true},
      {"centre_5pass", with(with(three, {{16, 16, 16}, 75}), {{16, 16, 16}, 75}), 2},
      {"window_mean_4pass", piv::CorrelationSettings{}.passes, 2, {}, false, true, mean, 0},
  };
  double reference_s = 0;
  for (const Variant& v : variants) {
    if (!all_variants && !v.always) continue;
    if (default_only && v.name.rfind("default_4pass", 0) != 0) continue;
    tbb::global_control limit(tbb::global_control::max_allowed_parallelism, v.threads);
    piv::CorrelationSettings settings;
    settings.passes = v.passes;
    settings.fft_planning = v.planning;
    settings.prefilter = v.prefilter;
    settings.predictor = v.predictor;
    settings.predictor_smoothing = v.smoothing;
    settings.early_interpolation = v.early;
    if (v.planning == piv::FftPlanning::measure)  // plan outside the timing, as a live run does
      for (const auto& p : v.passes) piv::FftCorrelator::shared(p.window, v.planning);
    piv::CorrelationResult r;
    const auto [s, cpu] = seconds_of([&] { r = piv::correlate_volumes(a, b, settings); });
    if (reference_s == 0) reference_s = cpu;
    const auto& last = r.passes.back();
    double deform = 0, correlate = 0;
    std::size_t outliers = 0;
    for (const auto& p : r.passes) {
      deform += p.deform_s;
      correlate += p.correlate_s;
      outliers += p.validation.outliers;
    }
    const sim::FieldErrors e = sim::field_errors(r.field, flow, voxel_mm);
    // The vectors' bits: equal hashes mean bit-identical vectors (between builds).
    std::uint64_t hash = bench::kFnvOffset;
    for (const auto* c : {&r.field.dx_mm, &r.field.dy_mm, &r.field.dz_mm}) hash = bench::bits_hash(*c, hash);
    // Away from the axis band (the final windows that reach the ring's axis, where the exact
    // u and w jump: sim::in_ring_axis_band).
    const double half_window_mm = 0.5 * v.passes.back().window[0] * voxel_mm;
    const sim::FieldErrors off = sim::field_errors(r.field, flow, voxel_mm, 1, 0, [&](const sim::Point3& x) {
      return !sim::in_ring_axis_band(flow, x, half_window_mm);
    });
    std::printf(
        "bench=piv_ring volume=%dx%dx%d variant=%s threads=%d seconds=%.2f cpu_s=%.2f cpu_ratio=%.2f "
        "deform_s=%.2f correlate_s=%.2f uncertainty_s=%.2f final_windows=%zu final_us_per_window=%.1f "
        "outliers=%zu rms_x=%.5f rms_y=%.5f rms_z=%.5f rms=%.5f max_displacement=%.2f "
        "rms_over_max=%.4f off_axis_band_n=%zu off_axis_band_rms_u=%.3f off_axis_band_rms_v=%.3f "
        "off_axis_band_rms_w=%.3f field_hash=%016llx\n",
        shape[0], shape[1], shape[2], v.name.c_str(), v.threads, s, cpu, cpu / reference_s, deform, correlate,
        last.uncertainty_s, last.windows, 1e6 * last.correlate_s / double(last.windows), outliers, e.rms[0], e.rms[1],
        e.rms[2], std::sqrt(e.rms[0] * e.rms[0] + e.rms[1] * e.rms[1] + e.rms[2] * e.rms[2]), e.max_truth_voxels,
        std::sqrt(e.rms[0] * e.rms[0] + e.rms[1] * e.rms[1] + e.rms[2] * e.rms[2]) / e.max_truth_voxels, off.compared,
        off.rms[0], off.rms[1], off.rms[2], (unsigned long long)hash);
    std::fflush(stdout);
  }
}

// Where the ring vortex's error sits. Regions of the final vector grid, disjoint, in this order:
//   axis:   the window reaches the ring's axis (|x - x_c| and |z - z_c| <= half a window), where
//           the exact u and w flip sign (sim::in_ring_axis_band);
//   border: the window's first or last voxel within 8 voxels (v_rc, the largest displacement)
//           of a face: particles there lose their partners;
//   core:   r < r_c from the core circle;
//   rest:   everything else.
// Per region and component: RMS against the node's truth (what field_errors reports), against the
// window-averaged truth (the midpoint truth averaged over the final window's voxels: what a
// window can measure at best) and the RMS of window-averaged minus node truth (the spatial
// filtering alone).
class Decomposition {
 public:
  Decomposition(const Grid3& g, const sim::RingVortexFlow& flow) : g_(g), flow_(flow) {
    // Midpoint truth (one fixed-point step, as field_errors) at every voxel, in voxels.
    for (auto& c : truth_) c.assign(g.count(), 0.f);
    tbb::parallel_for(tbb::blocked_range<int>(0, g.shape[2]), [&](const tbb::blocked_range<int>& r) {
      for (int k = r.begin(); k < r.end(); ++k)
        for (int j = 0; j < g.shape[1]; ++j)
          for (int i = 0; i < g.shape[0]; ++i) {
            const sim::Point3 x{g.coordinate_mm(0, i), g.coordinate_mm(1, j), g.coordinate_mm(2, k)};
            const sim::Point3 d0 = flow.displacement_mm(x);
            const sim::Point3 d = flow.displacement_mm({x[0] - d0[0] / 2, x[1] - d0[1] / 2, x[2] - d0[2] / 2});
            for (int a = 0; a < 3; ++a) truth_[a][g.index(i, j, k)] = float(d[a] / voxel_mm);
          }
    });
  }

  // Prints the table for `variant`'s field, whose final windows are `window` voxels wide.
  void report(const std::string& variant, const VectorField& f, int window) const {
    enum { axis, border, core, rest, regions };
    static const char* names[regions] = {"axis", "border", "core", "rest"};
    const Grid3& fg = f.grid;
    const double h = 0.5 * window;
    const auto& p = flow_.parameters();
    struct Sums {
      std::size_t n = 0;
      double meas[3] = {0, 0, 0}, filt[3] = {0, 0, 0}, box[3] = {0, 0, 0};
    };
    std::vector<int> region(fg.count());
    std::vector<std::array<double, 9>> sq(fg.count());  // per node: err^2 vs truth, vs box, box - truth
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, fg.count()), [&](const auto& r) {
      for (std::size_t n = r.begin(); n < r.end(); ++n) {
        const int i = int(n % fg.shape[0]), j = int(n / fg.shape[0] % fg.shape[1]),
                  k = int(n / (std::size_t(fg.shape[0]) * fg.shape[1]));
        const sim::Point3 x{fg.coordinate_mm(0, i), fg.coordinate_mm(1, j), fg.coordinate_mm(2, k)};
        std::array<int, 3> first;  // the window's first voxel per axis
        bool near_face = false;
        for (int a = 0; a < 3; ++a) {
          const double c = (x[a] - g_.origin_mm[a]) / g_.spacing_mm[a];
          first[a] = int(std::lround(c - (h - 0.5)));
          near_face |= first[a] < 8 || first[a] + window - 1 > g_.shape[a] - 1 - 8;
        }
        const double rho = std::hypot(x[0] - p.centre_mm[0], x[2] - p.centre_mm[2]);
        const double r_core = std::hypot(rho - 0.5 * p.ring_diameter_mm, x[1] - p.centre_mm[1]) / p.voxel_mm;
        region[n] = sim::in_ring_axis_band(flow_, x, h * voxel_mm) ? axis
                    : near_face                                    ? border
                    : r_core < p.core_radius_voxels                ? core
                                                                   : rest;
        sim::Point3 d = flow_.displacement_mm(x);
        d = flow_.displacement_mm({x[0] - d[0] / 2, x[1] - d[1] / 2, x[2] - d[2] / 2});
        const double got[3] = {f.dx_mm[n] / voxel_mm, f.dy_mm[n] / voxel_mm, f.dz_mm[n] / voxel_mm};
        for (int a = 0; a < 3; ++a) {
          double sum = 0;
          for (int z = first[2]; z < first[2] + window; ++z)
            for (int y = first[1]; y < first[1] + window; ++y) {
              const float* row = truth_[a].data() + g_.index(first[0], y, z);
              for (int v = 0; v < window; ++v) sum += row[v];
            }
          const double box = sum / (double(window) * window * window);
          const double t = d[a] / voxel_mm;
          sq[n][a] = (got[a] - t) * (got[a] - t);
          sq[n][3 + a] = (got[a] - box) * (got[a] - box);
          sq[n][6 + a] = (box - t) * (box - t);
        }
      }
    });
    Sums s[regions + 1];  // + all
    for (std::size_t n = 0; n < fg.count(); ++n) {
      if (!f.valid[n]) continue;
      for (Sums* t : {&s[region[n]], &s[regions]}) {
        ++t->n;
        for (int a = 0; a < 3; ++a) {
          t->meas[a] += sq[n][a];
          t->filt[a] += sq[n][3 + a];
          t->box[a] += sq[n][6 + a];
        }
      }
    }
    for (int r = 0; r <= regions; ++r) {
      const Sums& t = s[r];
      auto rms = [&](const double* v, int a) { return std::sqrt(v[a] / double(std::max<std::size_t>(t.n, 1))); };
      // share: the region's part of the all-vector mean square error, per component.
      auto share = [&](int a) { return s[regions].meas[a] > 0 ? t.meas[a] / s[regions].meas[a] : 0.0; };
      std::printf(
          "bench=piv_ring_regions variant=%s region=%s n=%zu rms_u=%.3f rms_v=%.3f rms_w=%.3f "
          "share_u=%.3f share_v=%.3f share_w=%.3f vs_window_mean_u=%.3f vs_window_mean_v=%.3f "
          "vs_window_mean_w=%.3f filtering_u=%.3f filtering_v=%.3f filtering_w=%.3f\n",
          variant.c_str(), r == regions ? "all" : names[r], t.n, rms(t.meas, 0), rms(t.meas, 1), rms(t.meas, 2),
          share(0), share(1), share(2), rms(t.filt, 0), rms(t.filt, 1), rms(t.filt, 2), rms(t.box, 0), rms(t.box, 1),
          rms(t.box, 2));
    }
    // Outside the band, by distance from the axis: how far the jump's influence reaches.
    for (int lo = 0; lo < 40; lo += 4) {
      std::size_t n_bin = 0;
      double m[3] = {0, 0, 0}, fl[3] = {0, 0, 0};
      for (std::size_t n = 0; n < fg.count(); ++n) {
        if (!f.valid[n] || region[n] == border) continue;
        const int i = int(n % fg.shape[0]), k = int(n / (std::size_t(fg.shape[0]) * fg.shape[1]));
        const double cheb = std::max(std::abs(fg.coordinate_mm(0, i) - p.centre_mm[0]),
                                     std::abs(fg.coordinate_mm(2, k) - p.centre_mm[2])) /
                            voxel_mm;
        if (cheb < lo || cheb >= lo + 4) continue;
        ++n_bin;
        for (int a = 0; a < 3; ++a) m[a] += sq[n][a], fl[a] += sq[n][3 + a];
      }
      const double d = double(std::max<std::size_t>(n_bin, 1));
      std::printf(
          "bench=piv_ring_axis_distance variant=%s chebyshev_voxels=%d-%d n=%zu rms_u=%.3f rms_v=%.3f "
          "rms_w=%.3f vs_window_mean_u=%.3f vs_window_mean_v=%.3f vs_window_mean_w=%.3f\n",
          variant.c_str(), lo, lo + 4, n_bin, std::sqrt(m[0] / d), std::sqrt(m[1] / d), std::sqrt(m[2] / d),
          std::sqrt(fl[0] / d), std::sqrt(fl[1] / d), std::sqrt(fl[2] / d));
    }
    std::fflush(stdout);
  }

 private:
  Grid3 g_;
  const sim::RingVortexFlow& flow_;
  std::array<std::vector<float>, 3> truth_;
};

void decompose(const std::array<int, 3>& shape, const std::vector<std::string>& variants) {
  const Grid3 g = centred_grid(shape[0], shape[1], shape[2]);
  const sim::RingVortexFlow flow(sim::RingVortexFlow::Parameters{});
  const auto pa = sim::particles_around(g, 2);
  const Volume a = sim::render_exact_volume(g, pa);
  const Volume b = sim::render_exact_volume(g, sim::displace(pa, flow));
  const Decomposition d(g, flow);
  tbb::global_control limit(tbb::global_control::max_allowed_parallelism, 2);
  for (const std::string& v : variants) {
    // "default", or "<c|m><smoothing>:<passes>": predictor at the centre (c) or window mean (m).
    piv::CorrelationSettings settings;
    if (v != "default") {
      settings.predictor = v[0] == 'c' ? piv::PredictorBase::centre : piv::PredictorBase::window_mean;
      settings.predictor_smoothing = v[1] - '0';
      settings.passes = piv::parse_passes(v.substr(3));
    }
    piv::CorrelationResult r;
    const auto [s, cpu] = seconds_of([&] { r = piv::correlate_volumes(a, b, settings); });
    std::printf("bench=piv_ring_decompose variant=%s seconds=%.2f cpu_s=%.2f\n", v.c_str(), s, cpu);
    d.report(v, r.field, settings.passes.back().window[0]);
  }
}

}  // namespace

int main(int argc, char** argv) {
  const bool quick = argc > 1 && std::strcmp(argv[1], "--quick") == 0;
  if (argc > 1 && std::strcmp(argv[1], "--decompose") == 0) {
    decompose({300, 200, 200}, std::vector<std::string>(argv + 2, argv + argc));
    return 0;
  }
  if (argc > 1 && std::strcmp(argv[1], "--default") == 0) {
    ring_vortex({300, 200, 200}, false, true);
    return 0;
  }
  if (quick) {
    uniform_shifts(48);
    ring_vortex({128, 96, 96}, true);
  } else {
    uniform_shifts(96);
    ring_vortex({300, 200, 200}, false);
  }
  return 0;
}
