// Correlation benchmark (paper sec 6.3-6.4): sub-voxel accuracy on exact-particle volumes,
// the ring vortex at 300x200x200 (RMS per component), and the time of that correlation.
//
//   build/bin/bench_piv [--quick]
//
// Prints one machine-readable line per figure (key=value); docs/benchmarks.md records them.
#include <sys/resource.h>
#include <tbb/global_control.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <functional>
#include <string>

#include "core/piv/fft_correlator.hpp"
#include "core/piv/multipass.hpp"
#include "core/sim/exact_volume.hpp"
#include "core/sim/field_errors.hpp"
#include "core/sim/flows.hpp"
#include "core/sim/particles.hpp"

using namespace plenopiv;

namespace {

constexpr double voxel_mm = 0.1;
constexpr double particles_per_voxel = 0.0023;  // 0.5 ppm: ~28 000 particles in 300x200x200

Grid3 centred_grid(int nx, int ny, int nz) {
  Grid3 g;
  g.shape = {nx, ny, nz};
  g.spacing_mm = {voxel_mm, voxel_mm, voxel_mm};
  for (int a = 0; a < 3; ++a) g.origin_mm[a] = -0.5 * (g.shape[a] - 1) * voxel_mm;
  return g;
}

// Particles in a box 4 voxels larger than the volume on every side (they enter and leave).
std::vector<sim::Point3> particles_for(const Grid3& g, std::uint64_t seed) {
  sim::Box box;
  double voxels = 1;
  for (int a = 0; a < 3; ++a) {
    box.min_mm[a] = g.origin_mm[a] - 4 * voxel_mm;
    box.max_mm[a] = g.origin_mm[a] + (g.shape[a] + 3) * voxel_mm;
    voxels *= g.shape[a] + 7;
  }
  return sim::random_particles(box, std::size_t(particles_per_voxel * voxels), seed);
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
  return {std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count(),
          cpu_seconds() - c0};
}

void uniform_shifts(int n) {
  const Grid3 g = centred_grid(n, n, n);
  const auto pa = particles_for(g, 1);
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
      std::printf("bench=piv_uniform volume=%d^3 prefilter=%d shift_voxel=%.1f vectors=%s n=%zu "
                  "bias_x=%.4f bias_y=%.4f bias_z=%.4f rms_x=%.4f rms_y=%.4f rms_z=%.4f\n",
                  n, int(prefilter), t, skip ? "interior" : "all", s.compared, s.bias[0], s.bias[1], s.bias[2],
                  s.rms[0], s.rms[1], s.rms[2]);
    }
  }
}

// `all_variants`: also the slower pass schedules and FFTW_MEASURE (quick mode only: at full
// scale each costs a minute of the shared machine).
void ring_vortex(const std::array<int, 3>& shape, bool all_variants) {
  const Grid3 g = centred_grid(shape[0], shape[1], shape[2]);
  const sim::RingVortexFlow flow(sim::RingVortexFlow::Parameters{});  // the paper's ring
  const auto pa = particles_for(g, 2);
  const Volume a = sim::render_exact_volume(g, pa);
  const Volume b = sim::render_exact_volume(g, sim::displace(pa, flow));
  struct Variant {
    std::string name;
    std::vector<piv::PassSettings> passes;
    int threads;
    piv::FftPlanning planning = piv::FftPlanning::estimate;
    bool always = false;
    bool prefilter = true;
  };
  const std::vector<Variant> variants{
      {"default_3pass_2threads", piv::CorrelationSettings{}.passes, 2, {}, true},
      {"default_3pass_1thread", piv::CorrelationSettings{}.passes, 1, {}, true},
      {"default_3pass_fftw_measure", piv::CorrelationSettings{}.passes, 2, piv::FftPlanning::measure},
      {"3pass_32_24_16", {{{32, 32, 32}, 50}, {{24, 24, 24}, 75}, {{16, 16, 16}, 75}}, 2},
      {"4pass_32_24_16_16", {{{32, 32, 32}, 50}, {{24, 24, 24}, 75}, {{16, 16, 16}, 75}, {{16, 16, 16}, 75}}, 2},
      {"default_3pass_no_prefilter", piv::CorrelationSettings{}.passes, 2, {}, true, false},
      {"single_pass_16", {{{16, 16, 16}, 75}}, 2, {}, true},
      {"5pass", {{{32, 32, 32}, 50}, {{24, 24, 24}, 75}, {{16, 16, 16}, 75}, {{16, 16, 16}, 75},
                 {{16, 16, 16}, 75}}, 2},
  };
  double reference_s = 0;
  for (const Variant& v : variants) {
    if (!all_variants && !v.always) continue;
    tbb::global_control limit(tbb::global_control::max_allowed_parallelism, v.threads);
    piv::CorrelationSettings settings;
    settings.passes = v.passes;
    settings.fft_planning = v.planning;
    settings.prefilter = v.prefilter;
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
    std::printf("bench=piv_ring volume=%dx%dx%d variant=%s threads=%d seconds=%.2f cpu_s=%.2f cpu_ratio=%.2f "
                "deform_s=%.2f correlate_s=%.2f final_windows=%zu final_us_per_window=%.1f "
                "outliers=%zu rms_x=%.3f rms_y=%.3f rms_z=%.3f rms=%.3f max_displacement=%.2f "
                "rms_over_max=%.4f\n",
                shape[0], shape[1], shape[2], v.name.c_str(), v.threads, s, cpu, cpu / reference_s,
                deform, correlate, last.windows, 1e6 * last.correlate_s / double(last.windows),
                outliers, e.rms[0], e.rms[1], e.rms[2],
                std::sqrt(e.rms[0] * e.rms[0] + e.rms[1] * e.rms[1] + e.rms[2] * e.rms[2]),
                e.max_truth_voxels,
                std::sqrt(e.rms[0] * e.rms[0] + e.rms[1] * e.rms[1] + e.rms[2] * e.rms[2]) /
                    e.max_truth_voxels);
    std::fflush(stdout);
  }
}

}  // namespace

int main(int argc, char** argv) {
  const bool quick = argc > 1 && std::strcmp(argv[1], "--quick") == 0;
  if (quick) {
    uniform_shifts(48);
    ring_vortex({128, 96, 96}, true);
  } else {
    uniform_shifts(96);
    ring_vortex({300, 200, 200}, false);
  }
  return 0;
}
