// The shipped run-paper.yaml's two tiers on a shear pair through a rotated, offset, jittered paper
// microlens array: the frames are rendered through the true array and processed with it as the
// calibration (the resampling path every calibrated camera takes), so that the figure is the
// tiers', not the calibration's. Voxels here are the paper's 0.125 mm, whatever CONFIG's. u and w
// grow along y (-2 to +2 voxels over the box, both across the focal plane's depth); FLOW uniform
// moves every particle by (2.32, 1.36, 2) voxels instead (a lateral shift off the voxel lattice
// with the depth one, bench_depth_response's). Per tier: set-up, first and in-a-run time per pair,
// and RMS error, bias and gain per component against the truth; the full tier once more with w
// through MART's depth response (reconstruction.depth_response_ppm at the pair's seeding).
// w's gain per depth band follows (near the focal plane the mirror ambiguity limits it), then the
// per-vector uncertainty's ratio to the true error and its coverage.
//   build/bin/bench_rotated_shear [DEGREES] [PPM] [both|full|plain] [CONFIG] [SEED] [shear|uniform]
// (defaults 0.1 deg, 0.5 ppm, both tiers, systemd/config/run-paper.yaml, particle set 2026, the
// shear; full: the full tier alone, plain: without its depth-response row; CONFIG: any run.yaml or
// process.yaml whose volume is the paper's box, or a box within it; SEED: another particle set)
#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <string>

#include "bench/bench_support.hpp"
#include "bench/simulated_calibration.hpp"
#include "core/base/yaml_access.hpp"
#include "core/calib/nominal_calibration.hpp"
#include "core/optics/camera_file.hpp"
#include "core/process/pair_processor.hpp"
#include "core/process/process.hpp"
#include "core/sim/field_errors.hpp"
#include "core/sim/flows.hpp"
#include "core/sim/particles.hpp"
#include "core/sim/render.hpp"

using namespace plenopiv;
namespace fs = std::filesystem;

namespace {

using bench::now_s;

}  // namespace

int main(int argc, char** argv) {
  const double degrees = argc > 1 ? std::atof(argv[1]) : 0.1;
  const double ppm = argc > 2 ? std::atof(argv[2]) : 0.5;
  const std::string tiers = argc > 3 ? argv[3] : "both";
  const long seed = argc > 5 ? std::atol(argv[5]) : 2026;
  const std::string flow_name = argc > 6 ? argv[6] : "shear";
  if (!(degrees >= 0 && degrees < 5) || !(ppm > 0 && ppm <= 5) ||
      (tiers != "both" && tiers != "full" && tiers != "plain") || seed < 1 ||
      (flow_name != "shear" && flow_name != "uniform")) {
    std::fprintf(stderr,
                 "usage: bench_rotated_shear [DEGREES in [0, 5)] [PPM in (0, 5]] [both|full|plain] [CONFIG] "
                 "[SEED >= 1] [shear|uniform]; got %g deg, %g ppm, %s, seed %ld, %s\n",
                 degrees, ppm, tiers.c_str(), seed, flow_name.c_str());
    return 2;
  }
  const bool full_only = tiers != "both", plain_only = tiers == "plain";
  const fs::path config_dir = fs::path(PLENOPIV_SOURCE_DIR) / "systemd/config";
  const optics::CameraModel camera = optics::load_camera_file(config_dir / "camera-fahringer2015.yaml");
  const fs::path config = argc > 4 ? fs::path(argv[4]) : config_dir / "run-paper.yaml";
  const YAML::Node run_yaml = YAML::LoadFile(config.string());
  const std::string config_name = config.filename().string();
  const process::ProcessSpec spec =
      process::process_spec_from(YamlMap(process::processing_part(run_yaml), config_name));

  // The true array: the nominal lattice rotated, offset by a fraction of a lens, each lens jittered
  // by 1 um (0.14 px).
  const calib::LoadedCalibration truth = bench::simulated_calibration(camera, degrees, {0.011, -0.007}, 0.001);

  const Grid3& g = spec.full.grid;
  const double voxel = g.spacing_mm[0];
  const double half_y = 0.5 * g.shape[1] * voxel;
  // The flow and the errors in the paper's voxels (0.125 mm, the lens pitch in object space)
  // whatever the config's: a config on finer voxels meets the same flow and is scored alike.
  constexpr double unit = 0.125;
  const double rate = 2 * unit / half_y;  // u and w: +-2 voxels at the box's y faces
  const sim::LinearShear shear({rate, 0, rate}, 1, 0.0);
  const sim::UniformFlow uniform({2.32 * unit, 1.36 * unit, 2 * unit});
  const sim::Flow& flow = flow_name == "uniform" ? static_cast<const sim::Flow&>(uniform) : shear;
  const double voxel_z = g.spacing_mm[2];  // run-paper.yaml's voxels are deeper than wide
  const sim::Box box{
      {g.origin_mm[0] - 0.5 * voxel - 1, -half_y - 1, g.origin_mm[2] - 0.5 * voxel_z - 1},
      {g.origin_mm[0] + (g.shape[0] - 0.5) * voxel + 1, half_y + 1, g.origin_mm[2] + (g.shape[2] - 0.5) * voxel_z + 1}};
  const std::size_t count = sim::particle_count_from_ppm(camera, box, ppm);
  const auto pa = sim::random_particles(box, count, std::uint64_t(seed));
  const auto pb = sim::displace(pa, flow);
  sim::RenderOptions ro;
  ro.rays_per_particle = 5000;
  double t = now_s();
  const ImageU16 a = sim::render(camera, truth.lenses, pa, ro, 1).image;
  const ImageU16 b = sim::render(camera, truth.lenses, pb, ro, 2).image;
  std::printf("bench=rotated_shear degrees=%.2f ppm=%.3f particles=%zu seed=%ld flow=%s render_s=%.1f\n", degrees, ppm,
              count, seed, flow_name.c_str(), now_s() - t);
  std::fflush(stdout);

  // The live tier, the full tier, and the full tier with w through MART's depth response measured
  // at this seeding (reconstruction.depth_response_ppm; its set-up time includes the response's
  // four simulated pairs).
  struct Row {
    process::Tier tier;
    bool depth_response;
  };
  for (const Row row :
       {Row{process::Tier::live, false}, Row{process::Tier::full, false}, Row{process::Tier::full, true}}) {
    const process::Tier tier = row.tier;
    if (full_only && tier != process::Tier::full) continue;
    if (plain_only && row.depth_response) continue;
    process::ProcessSettings s = spec.settings(tier, config_name);
    s.depth_response_ppm = row.depth_response ? ppm : 0.0;  // whatever CONFIG says
    const char* variant = s.depth_response_ppm > 0 ? "depth_response" : "plain";
    t = now_s();
    const process::PairProcessor processor(camera, truth, s);
    const double setup_s = now_s() - t;
    t = now_s();
    processor.process(a, b);
    const double first_s = now_s() - t;
    t = now_s();
    const process::PairResult r = processor.process(a, b);
    const double pair_s = now_s() - t;
    // Errors in the paper's voxels, whatever the tier's.
    const sim::FieldErrors e = sim::field_errors(r.correlation.field, flow, unit, 3);
    std::printf(
        "bench=rotated_shear tier=%s variant=%s config=%s degrees=%.2f voxel_mm=%g voxel_z_mm=%g pixel_binning=%d "
        "iterations=%d "
        "setup_s=%.2f first_s=%.2f pair_s=%.2f rms_u=%.3f rms_v=%.3f rms_w=%.3f bias_u=%.3f bias_v=%.3f bias_w=%.3f "
        "gain_u=%.3f "
        "gain_w=%.3f valid=%.3f resampled=%d peak_rss_gb=%.2f\n",
        process::tier_name(tier), variant, config_name.c_str(), degrees, s.grid.spacing_mm[0], s.grid.spacing_mm[2],
        s.pixel_binning, s.mart.iterations, setup_s, first_s, pair_s, e.rms[0], e.rms[1], e.rms[2], e.bias[0],
        e.bias[1], e.bias[2], e.gain[0], e.gain[2],
        r.correlation.field.grid.count() ? double(e.compared) / double(r.correlation.field.grid.count()) : 0.0,
        int(processor.op().resampler() != nullptr), bench::peak_rss_gb());
    // w's gain by distance from the focal plane (z = 0), mm.
    std::printf("bench=rotated_shear_depth tier=%s variant=%s ppm=%.3f config=%s", process::tier_name(tier), variant,
                ppm, config_name.c_str());
    const std::array<double, 6> edges{0, 2, 4, 8, 10, 1e9};
    for (std::size_t band = 0; band + 1 < edges.size(); ++band) {
      const sim::FieldErrors eb = sim::field_errors(r.correlation.field, flow, unit, 3, 0, [&](const sim::Point3& p) {
        return std::abs(p[2]) >= edges[band] && std::abs(p[2]) < edges[band + 1];
      });
      std::printf(" gain_w_%g_%g=%.3f bias_w_%g_%g=%.3f", edges[band], std::min(edges[band + 1], 99.0), eb.gain[2],
                  edges[band], std::min(edges[band + 1], 99.0), eb.bias[2]);
    }
    std::printf("\n");
    // The per-vector uncertainty against the true errors: RMS sigma / RMS error and the fraction
    // within +-1 and +-2 sigma per component; w's ratio by distance from the focal plane.
    const sim::UncertaintyCheck c = sim::uncertainty_check(r.correlation.field, flow, unit, 3, 0);
    std::printf("bench=rotated_shear_sigma tier=%s variant=%s", process::tier_name(tier), variant);
    for (std::size_t a = 0; a < 3; ++a)
      std::printf(" ratio_%c=%.3f within_1sigma_%c=%.3f within_2sigma_%c=%.3f", "uvw"[a],
                  c.rms_sigma[a] / c.rms_error[a], "uvw"[a], c.within_1[a], "uvw"[a], c.within_2[a]);
    for (std::size_t band = 0; band + 1 < edges.size(); ++band) {
      const sim::UncertaintyCheck cb = sim::uncertainty_check(
          r.correlation.field, flow, unit, 3, 0,
          [&](const sim::Point3& p) { return std::abs(p[2]) >= edges[band] && std::abs(p[2]) < edges[band + 1]; });
      std::printf(" ratio_w_%g_%g=%.3f", edges[band], std::min(edges[band + 1], 99.0),
                  cb.rms_sigma[2] / cb.rms_error[2]);
    }
    std::printf("\n");
    std::fflush(stdout);
  }
  return 0;
}
