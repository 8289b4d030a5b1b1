// Per-vector uncertainty benchmark: predicted sigma against the measured RMS error, per component
// and depth band, and the coverage of +-1 and +-2 sigma, on exact-particle and reconstructed cases.
//
//   build/bin/bench_uncertainty [--quick] [--exact-only [--window-mean] | --reconstructed-only [--sets N]]
//                               [--with-paper-ring]
//   build/bin/bench_uncertainty --cost N   (N^3 voxels: the correlation with and without the uncertainty)
//
// Exact particles: 96^3 voxels (--quick: 64^3) at 0.5 ppm, core/piv's default correlation: a
// uniform shift among dim particles that differ between the exposures (noise), a shear in u and
// w along y, and a ring vortex scored off its axis band; each with no final smoothing and one
// pass (--window-mean: with the window-mean predictor instead of the centre one); with
// --with-paper-ring also the paper's ring (300x200x200 voxels, sec 6.4; and 300x200x100, twice as deep), and
// reconstructed from the paper's camera with run-paper.yaml's full tier, with and without the depth response.
// Reconstructed: the small camera (a 6 mm cube: 48 voxels of 0.125 mm across, process.yaml's depth voxel) through
// process::PairProcessor with the shipped systemd/config/process.yaml settings: a uniform shift (by fractions of a
// voxel sideways: MART reconstructs a pair moved by whole voxels sideways alike in both exposures), a shear, the ring;
// each also with MART's depth response (reconstruction.depth_response_ppm at the pairs' 0.5 ppm); on
// --sets particle sets (default 8, --quick 2), pooled: a depth third of one set's cube holds a few
// hundred vectors whose errors are alike over a window's reach, so one set's ratio there scatters
// from set to set by more than the 30 % target. One line per case, band and component (key=value),
// with the sets' own ratios' range; docs/benchmarks.md records them.
#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <functional>
#include <string>
#include <vector>

#include "bench/bench_support.hpp"
#include "core/base/yaml_access.hpp"
#include "core/calib/nominal_calibration.hpp"
#include "core/optics/camera_file.hpp"
#include "core/piv/multipass.hpp"
#include "core/process/pair_processor.hpp"
#include "core/process/process.hpp"
#include "core/sim/exact_volume.hpp"
#include "core/sim/field_errors.hpp"
#include "core/sim/flows.hpp"
#include "core/sim/particles.hpp"
#include "core/sim/render.hpp"

using namespace plenopiv;

namespace {

using bench::now_s;

Grid3 centred_grid(std::array<int, 3> n, double voxel_mm) {
  Grid3 g;
  g.shape = n;
  g.spacing_mm = {voxel_mm, voxel_mm, voxel_mm};
  for (int a = 0; a < 3; ++a) g.origin_mm[a] = -0.5 * (n[a] - 1) * voxel_mm;
  return g;
}

constexpr int kBands = 4;  // thirds of the field's depth (near, middle, far), and all
using BandChecks = std::array<sim::UncertaintyCheck, kBands>;

BandChecks check_bands(const VectorField& f, const sim::Flow& flow, double voxel_mm,
                       const std::function<bool(const sim::Point3&)>& keep) {
  const Grid3& g = f.grid;
  const double z0 = g.origin_mm[2], depth = (g.shape[2] - 1) * g.spacing_mm[2];
  BandChecks checks;
  for (int band = 0; band < kBands; ++band) {
    const auto include = [&](const sim::Point3& x) {
      if (keep && !keep(x)) return false;
      if (band == kBands - 1) return true;
      const int b = std::min(2, int(3 * (x[2] - z0) / (depth + 1e-9)));
      return b == band;
    };
    checks[std::size_t(band)] = sim::uncertainty_check(f, flow, voxel_mm, 1, 1, include);
  }
  return checks;
}

// The checks of several particle sets as one: every figure is a mean over the vectors compared,
// so each set weighs by its count (RMS values through their squares).
sim::UncertaintyCheck pool(const std::vector<sim::UncertaintyCheck>& sets) {
  sim::UncertaintyCheck p;
  for (const sim::UncertaintyCheck& c : sets) {
    if (c.compared == 0) continue;
    const double n = double(c.compared);
    p.compared += c.compared;
    for (std::size_t a = 0; a < 3; ++a) {
      p.rms_error[a] += n * c.rms_error[a] * c.rms_error[a];
      p.rms_sigma[a] += n * c.rms_sigma[a] * c.rms_sigma[a];
      p.bias[a] += n * c.bias[a];
      p.within_1[a] += n * c.within_1[a];
      p.within_2[a] += n * c.within_2[a];
    }
  }
  const double n = double(p.compared);
  for (std::size_t a = 0; a < 3; ++a) {
    p.rms_error[a] = std::sqrt(p.rms_error[a] / n);
    p.rms_sigma[a] = std::sqrt(p.rms_sigma[a] / n);
    p.bias[a] /= n;
    p.within_1[a] /= n;
    p.within_2[a] /= n;
  }
  return p;
}

// One row per depth band and component; with several particle sets, the pooled figures and the
// range of the sets' own sigma / error.
void print_bands(const std::string& kind, const std::string& name, const std::vector<BandChecks>& sets) {
  const char* bands[] = {"near", "middle", "far", "all"};
  for (std::size_t band = 0; band < kBands; ++band) {
    std::vector<sim::UncertaintyCheck> per_set;
    for (const BandChecks& s : sets) per_set.push_back(s[band]);
    const sim::UncertaintyCheck c = pool(per_set);
    for (std::size_t a = 0; a < 3; ++a) {
      std::printf(
          "bench=uncertainty kind=%s case=%s band=%s component=%c vectors=%zu rms_error=%.4f bias=%.4f "
          "rms_sigma=%.4f ratio=%.3f within_1sigma=%.3f within_2sigma=%.3f",
          kind.c_str(), name.c_str(), bands[band], "uvw"[a], c.compared, c.rms_error[a], c.bias[a], c.rms_sigma[a],
          c.rms_sigma[a] / c.rms_error[a], c.within_1[a], c.within_2[a]);
      if (per_set.size() > 1) {
        double lo = INFINITY, hi = -INFINITY;
        for (const sim::UncertaintyCheck& s : per_set) {
          lo = std::min(lo, s.rms_sigma[a] / s.rms_error[a]);
          hi = std::max(hi, s.rms_sigma[a] / s.rms_error[a]);
        }
        std::printf(" sets=%zu set_ratio_min=%.3f set_ratio_max=%.3f", per_set.size(), lo, hi);
      }
      std::printf("\n");
    }
  }
  std::fflush(stdout);
}

void report(const std::string& kind, const std::string& name, const VectorField& f, const sim::Flow& flow,
            double voxel_mm, const std::function<bool(const sim::Point3&)>& keep) {
  print_bands(kind, name, {check_bands(f, flow, voxel_mm, keep)});
}

void exact_cases(int n, bool window_mean) {
  const double voxel = 0.1;
  for (int smoothing : {0, 1}) {
    piv::CorrelationSettings settings;
    settings.dt_s = 1e-3;
    settings.final_smoothing = smoothing;
    if (window_mean) settings.predictor = piv::PredictorBase::window_mean;
    const std::string suffix = std::string(smoothing ? "_smoothed" : "") + (window_mean ? "_window_mean" : "");
    {
      const Grid3 g = centred_grid({n, n, n}, voxel);
      const auto pa = sim::particles_around(g, 51);
      const sim::UniformFlow flow({0.03, -0.06, 0.12});
      Volume a = sim::render_exact_volume(g, pa), b = sim::render_exact_volume(g, sim::displace(pa, flow));
      for (Volume* v : {&a, &b}) {
        std::vector<sim::Point3> noise;
        for (std::uint64_t k = 0; k < 4; ++k) {
          const auto p = sim::particles_around(g, (v == &a ? 60 : 70) + k);
          noise.insert(noise.end(), p.begin(), p.end());
        }
        const Volume dim = sim::render_exact_volume(g, noise);
        for (std::size_t i = 0; i < v->data.size(); ++i) v->data[i] += 0.25f * dim.data[i];
      }
      const double t = now_s();
      const auto r = piv::correlate_volumes(a, b, settings);
      std::printf("bench=uncertainty kind=exact case=uniform_noise%s correlate_s=%.2f uncertainty_s=%.2f\n",
                  suffix.c_str(), now_s() - t, r.passes.back().uncertainty_s);
      report("exact", "uniform_noise" + suffix, r.field, flow, voxel, {});
    }
    {
      const Grid3 g = centred_grid({n, n, n}, voxel);
      const auto pa = sim::particles_around(g, 52);
      const sim::LinearShear flow({0.05, 0, 0.05}, 1, 0.0);  // +-2.4 voxels across 96
      const Volume a = sim::render_exact_volume(g, pa), b = sim::render_exact_volume(g, sim::displace(pa, flow));
      const auto r = piv::correlate_volumes(a, b, settings);
      report("exact", "shear" + suffix, r.field, flow, voxel, {});
    }
    {
      const Grid3 g = centred_grid({n, n * 2 / 3, n * 2 / 3}, voxel);
      sim::RingVortexFlow::Parameters rv;
      rv.voxel_mm = voxel;
      rv.ring_diameter_mm = 0.5 * n * voxel;
      rv.core_radius_voxels = n / 6.0;
      rv.core_displacement_voxels = 4;
      const sim::RingVortexFlow flow(rv);
      const auto pa = sim::particles_around(g, 53);
      const Volume a = sim::render_exact_volume(g, pa), b = sim::render_exact_volume(g, sim::displace(pa, flow));
      const auto r = piv::correlate_volumes(a, b, settings);
      const double half = 0.5 * settings.passes.back().window[0] * voxel;
      report("exact", "ring_off_axis_band" + suffix, r.field, flow, voxel,
             [&](const sim::Point3& x) { return !sim::in_ring_axis_band(flow, x, half); });
    }
  }
}

// The paper's ring (sec 6.4: 300x200x200 voxels of 0.1 mm, core radius 40 voxels, 8 voxels at
// the core) on exact-particle volumes, off its axis band, with core/piv's default correlation and
// with one final smoothing pass. deep: the same box in voxels twice as deep (300x200x100, as
// run-paper.yaml's), the default passes' windows and depth margin halved in depth (the same mm).
void paper_ring(bool deep) {
  const Grid3 cubes = centred_grid({300, 200, 200}, 0.1);
  Grid3 g = cubes;
  if (deep) {
    g.shape[2] = 100;
    g.spacing_mm[2] = 0.2;
    g.origin_mm[2] = -0.5 * (g.shape[2] - 1) * g.spacing_mm[2];
  }
  const sim::RingVortexFlow flow(sim::RingVortexFlow::Parameters{});
  const auto pa = sim::particles_around(cubes, 2015);  // the same particles on either grid
  const Volume a = sim::render_exact_volume(g, pa), b = sim::render_exact_volume(g, sim::displace(pa, flow));
  for (int smoothing : {0, 1}) {
    piv::CorrelationSettings settings;
    settings.dt_s = 1e-3;
    settings.final_smoothing = smoothing;
    if (deep)
      for (auto& pass : settings.passes) {
        pass.window[2] /= 2;
        pass.depth_margin /= 2;
      }
    const double t = now_s();
    const auto r = piv::correlate_volumes(a, b, settings);
    const std::string name = std::string(deep ? "paper_ring_deep_off_axis_band" : "paper_ring_off_axis_band") +
                             (smoothing ? "_smoothed" : "");
    std::printf("bench=uncertainty kind=exact case=%s correlate_s=%.2f uncertainty_s=%.2f\n", name.c_str(), now_s() - t,
                r.passes.back().uncertainty_s);
    const double half = 0.5 * settings.passes.back().window[0] * 0.1;
    report("exact", name, r.field, flow, 0.1,
           [&](const sim::Point3& x) { return !sim::in_ring_axis_band(flow, x, half); });
  }
}

// The uncertainty's cost: the same correlation with and without it (CPU seconds of the whole
// correlation, and the final pass's uncertainty step: the median of three), whether the vectors are
// the same bits, and a hash of the sigmas' bits (to compare builds of the uncertainty). With core/piv's
// default passes, and with run-paper.yaml's windows (16 x 16 x 8 voxels, the last pass at 75 %).
void cost(int n) {
  const Grid3 g = centred_grid({n, n, n}, 0.1);
  const auto pa = sim::particles_around(g, 51);
  const sim::UniformFlow flow({0.03, -0.06, 0.12});
  const Volume a = sim::render_exact_volume(g, pa), b = sim::render_exact_volume(g, sim::displace(pa, flow));
  piv::CorrelationSettings paper;
  paper.passes = {piv::PassSettings{{32, 32, 16}, 50, 0}, piv::PassSettings{{16, 16, 8}, 50, 2},
                  piv::PassSettings{{16, 16, 8}, 75, 0}};
  for (const auto& [name, settings] : {std::pair{"default", piv::CorrelationSettings{}}, std::pair{"16x16x8", paper}}) {
    piv::CorrelationSettings on = settings, off = settings;
    off.uncertainty = false;
    double cpu[2];
    std::uint64_t hash[2];
    std::uint64_t sigma_hash = 0;
    std::vector<double> uncertainty_s;
    piv::correlate_volumes(a, b, off);  // FFT plans and thread buffers made before either is timed
    for (int k = 0; k < 2; ++k) {
      const double c = bench::cpu_seconds();
      const auto r = piv::correlate_volumes(a, b, k ? off : on);
      cpu[k] = bench::cpu_seconds() - c;
      hash[k] = bench::bits_hash(r.field.dz_mm, bench::bits_hash(r.field.dy_mm, bench::bits_hash(r.field.dx_mm)));
      if (k == 0) {
        uncertainty_s.push_back(r.passes.back().uncertainty_s);
        sigma_hash = bench::bits_hash(r.field.sigma_dz_mm,
                                      bench::bits_hash(r.field.sigma_dy_mm, bench::bits_hash(r.field.sigma_dx_mm)));
      }
    }
    for (int k = 0; k < 2; ++k) uncertainty_s.push_back(piv::correlate_volumes(a, b, on).passes.back().uncertainty_s);
    std::sort(uncertainty_s.begin(), uncertainty_s.end());
    std::printf(
        "bench=uncertainty kind=cost voxels=%d^3 windows=%s cpu_with_s=%.3f cpu_without_s=%.3f extra=%.3f "
        "uncertainty_wall_s=%.3f same_vectors=%d sigma_hash=%016llx\n",
        n, name, cpu[0], cpu[1], cpu[0] / cpu[1] - 1, uncertainty_s[1], int(hash[0] == hash[1]),
        static_cast<unsigned long long>(sigma_hash));
  }
}

void reconstructed_cases(int sets) {
  const std::string dir = std::string(PLENOPIV_SOURCE_DIR) + "/systemd/config/";
  const auto camera = optics::load_camera_file(dir + "camera-small.yaml");
  const double voxel = 0.125;
  const int n = 48;
  const double h = 0.5 * n * voxel;
  process::ProcessSettings settings = process::load_process_settings(dir + "process.yaml");
  // A 6 mm cube across the focal plane in process.yaml's voxels (0.125 mm across, its depth voxel).
  const double voxel_z = settings.grid.spacing_mm[2];
  settings.grid = process::grid_for_extent({-h, -h, -h}, {h, h, h}, {voxel, voxel, voxel_z}, "bench");
  settings.correlation.dt_s = 1e-3;
  const calib::LoadedCalibration nominal = calib::nominal_calibration(camera);
  const process::PairProcessor processor(camera, nominal, settings);
  // The same settings with MART's depth response measured at the pairs' seeding: w through its
  // inverse, every sigma widened by the error the response's pairs show and the correlation's
  // sigma does not.
  process::ProcessSettings with_response = settings;
  with_response.depth_response_ppm = 0.5;
  const double setup_start = now_s();
  const process::PairProcessor calibrated(camera, nominal, with_response);
  std::printf("bench=uncertainty kind=reconstructed case=depth_response_setup setup_s=%.1f\n", now_s() - setup_start);
  const sim::Box box{{-h - 1, -h - 1, -h - 1}, {h + 1, h + 1, h + 1}};
  sim::RenderOptions ro;
  ro.rays_per_particle = 5000;
  const auto render = [&](const std::vector<sim::Point3>& p, std::uint64_t seed) {
    const auto r = sim::render(camera, nominal.lenses, p, ro, seed);
    ImageF f(r.image.width, r.image.height);
    for (std::size_t i = 0; i < f.size(); ++i) f.pixels[i] = r.image.pixels[i];
    return f;
  };
  sim::RingVortexFlow::Parameters rv;
  rv.voxel_mm = voxel;
  rv.ring_diameter_mm = 3.0;
  rv.core_radius_voxels = 8;
  rv.core_displacement_voxels = 3;
  const sim::RingVortexFlow ring(rv);
  const sim::UniformFlow uniform({0.29, 0.17, 0.25});   // 2.32, 1.36, 2 voxels
  const sim::LinearShear shear({0.1, 0, 0.1}, 1, 0.0);  // u and w +-2.4 voxels across y
  const std::pair<const char*, const sim::Flow*> flows[] = {
      {"uniform", &uniform}, {"shear", &shear}, {"ring_off_axis_band", &ring}};
  // Per case (flow, then without and with the response), the checks of every particle set.
  std::vector<std::vector<BandChecks>> checks(2 * std::size(flows));
  for (int set = 0; set < sets; ++set) {
    const auto pa = sim::random_particles(box, sim::particle_count_from_ppm(camera, box, 0.5), 2015 + set);
    const ImageF a = render(pa, 1 + 2 * std::uint64_t(set));
    for (std::size_t k = 0; k < std::size(flows); ++k) {
      const auto& [name, flow] = flows[k];
      const ImageF b = render(sim::displace(pa, *flow), 2 + 2 * std::uint64_t(set));
      std::function<bool(const sim::Point3&)> keep;
      if (flow == &ring) {
        const double half = 0.5 * settings.correlation.passes.back().window[0] * voxel;
        keep = [&, half](const sim::Point3& x) { return !sim::in_ring_axis_band(ring, x, half); };
      }
      for (const process::PairProcessor* p : {&processor, &calibrated}) {
        const std::string case_name = std::string(name) + (p == &calibrated ? "_depth_response" : "");
        const double t = now_s();
        const auto r = p->process(a, b);
        std::printf(
            "bench=uncertainty kind=reconstructed case=%s set=%d process_s=%.2f correlate_s=%.2f uncertainty_s=%.3f\n",
            case_name.c_str(), set, now_s() - t, r.times.correlate_s, r.correlation.passes.back().uncertainty_s);
        checks[2 * k + (p == &calibrated)].push_back(check_bands(r.correlation.field, *flow, voxel, keep));
      }
    }
  }
  for (std::size_t k = 0; k < std::size(flows); ++k)
    for (const int calibrated_case : {0, 1})
      print_bands("reconstructed", std::string(flows[k].first) + (calibrated_case ? "_depth_response" : ""),
                  checks[2 * k + std::size_t(calibrated_case)]);
}

// The paper's ring (sec 6.4) rendered on the paper's camera at 0.5 ppm and processed with
// run-paper.yaml's full tier (300x200x100 voxels, 0.125 x 0.25 mm), off its axis band; then once
// more with MART's depth response measured at the same seeding.
void paper_ring_reconstructed() {
  const std::string dir = std::string(PLENOPIV_SOURCE_DIR) + "/systemd/config/";
  const auto camera = optics::load_camera_file(dir + "camera-fahringer2015.yaml");
  const YAML::Node run_yaml = YAML::LoadFile(dir + "run-paper.yaml");
  process::ProcessSettings settings =
      process::process_spec_from(YamlMap(process::processing_part(run_yaml), "run-paper.yaml")).full;
  settings.correlation.dt_s = 1e-3;
  const Grid3& g = settings.grid;
  const double voxel = g.spacing_mm[0];
  sim::RingVortexFlow::Parameters rv;
  rv.voxel_mm = voxel;
  const sim::RingVortexFlow ring(rv);
  sim::Box box;
  for (int a = 0; a < 3; ++a) {
    box.min_mm[a] = g.origin_mm[a] - 0.5 * g.spacing_mm[a] - 1;
    box.max_mm[a] = g.origin_mm[a] + (g.shape[a] - 0.5) * g.spacing_mm[a] + 1;
  }
  const calib::LoadedCalibration nominal = calib::nominal_calibration(camera);
  const auto pa = sim::random_particles(box, sim::particle_count_from_ppm(camera, box, 0.5), 2015);
  sim::RenderOptions ro;
  ro.rays_per_particle = 5000;
  const ImageU16 a = sim::render(camera, nominal.lenses, pa, ro, 1).image;
  const ImageU16 b = sim::render(camera, nominal.lenses, sim::displace(pa, ring), ro, 2).image;
  const double half = 0.5 * settings.correlation.passes.back().window[0] * voxel;
  const auto keep = [&](const sim::Point3& x) { return !sim::in_ring_axis_band(ring, x, half); };
  for (const double ppm : {0.0, 0.5}) {
    settings.depth_response_ppm = ppm;
    const double setup_start = now_s();  // the operator, and the depth response where measured
    const process::PairProcessor processor(camera, nominal, settings);
    const double setup_s = now_s() - setup_start;
    const std::string name = ppm > 0 ? "paper_ring_off_axis_band_depth_response" : "paper_ring_off_axis_band";
    const double t = now_s();
    const auto r = processor.process(a, b);
    std::printf(
        "bench=uncertainty kind=reconstructed case=%s setup_s=%.1f process_s=%.2f correlate_s=%.2f "
        "uncertainty_s=%.3f\n",
        name.c_str(), setup_s, now_s() - t, r.times.correlate_s, r.correlation.passes.back().uncertainty_s);
    report("reconstructed", name, r.correlation.field, ring, voxel, keep);
  }
}

}  // namespace

int main(int argc, char** argv) {
  bool quick = false, exact = true, reconstructed = true, window_mean = false;
  int sets = 0;  // 0: the default
  int cost_voxels = 0;
  bool paper = false;
  for (int i = 1; i < argc; ++i) {
    if (!std::strcmp(argv[i], "--quick")) {
      quick = true;
    } else if (!std::strcmp(argv[i], "--exact-only")) {
      reconstructed = false;
    } else if (!std::strcmp(argv[i], "--cost") && i + 1 < argc) {
      cost_voxels = std::stoi(argv[++i]);
    } else if (!std::strcmp(argv[i], "--with-paper-ring")) {
      paper = true;
    } else if (!std::strcmp(argv[i], "--window-mean")) {
      window_mean = true;
    } else if (!std::strcmp(argv[i], "--reconstructed-only")) {
      exact = false;
    } else if (!std::strcmp(argv[i], "--sets") && i + 1 < argc && std::atoi(argv[i + 1]) > 0) {
      sets = std::atoi(argv[++i]);
    } else {
      std::fprintf(stderr,
                   "usage: bench_uncertainty [--quick] [--exact-only [--window-mean] | --reconstructed-only "
                   "[--sets N]] [--with-paper-ring] | --cost N\n");
      return 2;
    }
  }
  if (cost_voxels) {
    cost(cost_voxels);
    return 0;
  }
  if (exact) exact_cases(quick ? 64 : 96, window_mean);
  if (reconstructed) reconstructed_cases(sets ? sets : quick ? 2 : 8);
  if (paper) {
    paper_ring(false);
    paper_ring(true);
    if (reconstructed) paper_ring_reconstructed();
  }
  return 0;
}
