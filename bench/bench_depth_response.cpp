// MART's depth response (reconstruction.depth_response_ppm) over many particle sets: w's gain, bias
// and RMS error on the small camera, and how its sigma covers that error, without and with the
// response, per flow, as the mean (and for gain, bias and RMS its standard error) over the sets.
// On a small box a pair's w gain scatters from one particle set to the next by more than the few
// per cent a bias target asks for, so one set cannot say whether the response leaves a bias; the
// mean over sets can.
//
//   build/bin/bench_depth_response [--sets N] [--degrees D | --nominal] [--lens-offset-um X,Y]
//                                  [--jitter-um J] [--grid-shift-um X,Y] [--no-response]
//
// --sets (default 8, 2-64): particle sets, each its own frame A, rendered once and displaced by
// every flow. The true array: the nominal lattice rotated by --degrees (default 0.1, [0, 5)),
// offset by --lens-offset-um on the sensor (default 11,-7) and each lens jittered by --jitter-um
// (default 1), as bench_rotated_shear's; rendered through and processed with as the calibration (a
// jittered or rotated array's frames are resampled, as every calibrated camera's are); --nominal:
// the camera file's own array instead. The box: a 6 mm cube across the focal plane in process.yaml's
// voxels (0.125 mm across: one lens pitch at the camera's magnification; its depth voxel), moved
// sideways by --grid-shift-um, with process.yaml's settings; the response measured at the sets'
// 0.5 ppm (--no-response: not measured). Flows, in voxels of 0.125 mm: uniform (2.32, 1.36, +-2)
// (fractions of a voxel sideways), depth alone (0, 0, +-2), a shear of u and w (+-2.4 across y,
// v = 0) and the same with v at half their rate. One line per set and flow, then one summary line
// per flow (key=value).
#include <array>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include "bench/bench_support.hpp"
#include "bench/simulated_calibration.hpp"
#include "core/base/errors.hpp"
#include "core/calib/nominal_calibration.hpp"
#include "core/optics/camera_file.hpp"
#include "core/process/depth_response.hpp"
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

// Mean and standard error of the mean of `v` (at least two values).
struct MeanError {
  double mean = 0, error = 0;
};
MeanError mean_error(const std::vector<double>& v) {
  double sum = 0;
  for (const double x : v) sum += x;
  const double mean = sum / double(v.size());
  double spread = 0;
  for (const double x : v) spread += (x - mean) * (x - mean);
  return {mean, std::sqrt(spread / double(v.size() - 1) / double(v.size()))};
}

// w's figures of one flow over the sets, without (0) and with (1) the response, and u's and v's
// RMS error (the response leaves u and v as they are).
struct Scores {
  std::vector<double> gain[2], bias[2], rms[2], rms_u, rms_v;
  // w's predicted sigma against its true error: RMS sigma / RMS error, and the fractions of the
  // errors within +-1 and +-2 sigma.
  std::vector<double> sigma_ratio[2], within_1[2], within_2[2];
};

// Two comma-separated numbers ("X,Y") into `out`; false when `text` is not that.
bool parse_pair(const char* text, std::array<double, 2>& out) {
  char* end = nullptr;
  out[0] = std::strtod(text, &end);
  if (end == text || *end != ',') return false;
  const char* second = end + 1;
  out[1] = std::strtod(second, &end);
  return end != second && *end == '\0' && std::isfinite(out[0]) && std::isfinite(out[1]);
}

int usage() {
  std::fprintf(stderr,
               "usage: bench_depth_response [--sets N (2..64)] [--degrees D ([0, 5)) | --nominal] "
               "[--lens-offset-um X,Y] [--jitter-um J] [--grid-shift-um X,Y] [--no-response]\n");
  return 2;
}

}  // namespace

int main(int argc, char** argv) {
  int sets = 8;
  double degrees = 0.1, jitter_um = 1;
  std::array<double, 2> lens_offset_um{11, -7}, grid_shift_um{0, 0};
  bool nominal = false, response = true;
  for (int i = 1; i < argc; ++i) {
    const bool has_value = i + 1 < argc;
    if (!std::strcmp(argv[i], "--sets") && has_value)
      sets = std::atoi(argv[++i]);
    else if (!std::strcmp(argv[i], "--degrees") && has_value)
      degrees = std::atof(argv[++i]);
    else if (!std::strcmp(argv[i], "--nominal"))
      nominal = true;
    else if (!std::strcmp(argv[i], "--lens-offset-um") && has_value && parse_pair(argv[i + 1], lens_offset_um))
      ++i;
    else if (!std::strcmp(argv[i], "--jitter-um") && has_value)
      jitter_um = std::atof(argv[++i]);
    else if (!std::strcmp(argv[i], "--grid-shift-um") && has_value && parse_pair(argv[i + 1], grid_shift_um))
      ++i;
    else if (!std::strcmp(argv[i], "--no-response"))
      response = false;
    else
      return usage();
  }
  if (sets < 2 || sets > 64 || !(degrees >= 0 && degrees < 5) || !(jitter_um >= 0 && jitter_um <= 20)) return usage();
  const fs::path dir = fs::path(PLENOPIV_SOURCE_DIR) / "systemd/config";
  const optics::CameraModel camera = optics::load_camera_file(dir / "camera-small.yaml");
  const double voxel = 0.125, ppm = 0.5;
  const double h = 0.5 * 48 * voxel;
  process::ProcessSettings settings = process::load_process_settings(dir / "process.yaml");
  settings.grid =
      process::grid_for_extent({-h, -h, -h}, {h, h, h}, {voxel, voxel, settings.grid.spacing_mm[2]}, "bench");
  settings.correlation.dt_s = 1e-3;
  // The box moved sideways by a fraction of a voxel: where its voxels lie against the lenses' images.
  settings.grid.origin_mm[0] += 1e-3 * grid_shift_um[0];
  settings.grid.origin_mm[1] += 1e-3 * grid_shift_um[1];

  // The true array: the nominal lattice rotated, offset, each lens jittered (bench_rotated_shear's
  // defaults), or the camera file's own.
  const calib::LoadedCalibration truth =
      nominal ? calib::nominal_calibration(camera)
              : bench::simulated_calibration(camera, degrees, {1e-3 * lens_offset_um[0], 1e-3 * lens_offset_um[1]},
                                             1e-3 * jitter_um);

  const process::PairProcessor plain(camera, truth, settings);
  process::ProcessSettings with_response = settings;
  with_response.depth_response_ppm = ppm;
  std::printf(
      "bench=depth_response case=array array=%s degrees=%.2f lens_offset_um=%g,%g jitter_um=%g grid_shift_um=%g,%g "
      "resampled=%d\n",
      nominal ? "nominal" : "calibrated", nominal ? 0.0 : degrees, nominal ? 0.0 : lens_offset_um[0],
      nominal ? 0.0 : lens_offset_um[1], nominal ? 0.0 : jitter_um, grid_shift_um[0], grid_shift_um[1],
      int(plain.op().resampler() != nullptr));
  // A response the processor refuses (a layer that follows its outermost shifts by less than
  // process::kDepthResponseLeast of them) is reported, and the sets are processed without it alone.
  const double t = now_s();
  std::unique_ptr<const process::PairProcessor> corrected;
  if (response) {
    try {
      corrected = std::make_unique<const process::PairProcessor>(camera, truth, with_response);
      std::printf("bench=depth_response case=setup sets=%d setup_s=%.1f response=\"%s\"\n", sets, now_s() - t,
                  corrected->depth_response()->summary().c_str());
    } catch (const InputError& e) {
      std::printf("bench=depth_response case=setup sets=%d setup_s=%.1f refused=\"%s\"\n", sets, now_s() - t, e.what());
    }
  }
  std::fflush(stdout);

  const double rate = 2.4 * voxel / h;  // +-2.4 voxels at the box's y faces
  const sim::UniformFlow uniform_up({2.32 * voxel, 1.36 * voxel, 2 * voxel});
  const sim::UniformFlow uniform_down({2.32 * voxel, 1.36 * voxel, -2 * voxel});
  const sim::UniformFlow depth_up({0, 0, 2 * voxel});
  const sim::UniformFlow depth_down({0, 0, -2 * voxel});
  const sim::LinearShear shear({rate, 0, rate}, 1, 0.0);
  const sim::LinearShear shear_v({rate, 0.5 * rate, rate}, 1, 0.0);
  const std::pair<const char*, const sim::Flow*> flows[] = {
      {"uniform_up", &uniform_up}, {"uniform_down", &uniform_down},
      {"depth_up", &depth_up},     {"depth_down", &depth_down},
      {"shear", &shear},           {"shear_v", &shear_v}};
  std::vector<Scores> scores(std::size(flows));

  const sim::Box box{{-h - 1, -h - 1, -h - 1}, {h + 1, h + 1, h + 1}};
  const std::size_t count = sim::particle_count_from_ppm(camera, box, ppm);
  sim::RenderOptions ro;
  ro.rays_per_particle = 5000;
  for (int set = 0; set < sets; ++set) {
    // Seeds apart from the response's own sets (7001 + 2k and the next).
    const std::uint64_t seed = 90001 + 4 * std::uint64_t(set);
    const std::vector<sim::Point3> pa = sim::random_particles(box, count, seed);
    const ImageU16 a = sim::render(camera, truth.lenses, pa, ro, seed + 1).image;
    for (std::size_t f = 0; f < std::size(flows); ++f) {
      const sim::Flow& flow = *flows[f].second;
      const ImageU16 b = sim::render(camera, truth.lenses, sim::displace(pa, flow), ro, seed + 2).image;
      for (int k = 0; k < 2; ++k) {
        if (k && !corrected) {
          for (std::vector<double>* v : {&scores[f].gain[k], &scores[f].bias[k], &scores[f].rms[k],
                                         &scores[f].sigma_ratio[k], &scores[f].within_1[k], &scores[f].within_2[k]})
            v->push_back(std::nan(""));
          continue;
        }
        const process::PairResult r = (k ? *corrected : plain).process(a, b);
        const sim::FieldErrors e = sim::field_errors(r.correlation.field, flow, voxel, 0);
        if (k == 0) {
          scores[f].rms_u.push_back(e.rms[0]);
          scores[f].rms_v.push_back(e.rms[1]);
        }
        scores[f].gain[k].push_back(e.gain[2]);
        scores[f].bias[k].push_back(e.bias[2]);
        scores[f].rms[k].push_back(e.rms[2]);
        const sim::UncertaintyCheck c = sim::uncertainty_check(r.correlation.field, flow, voxel, 0, 0);
        scores[f].sigma_ratio[k].push_back(c.rms_sigma[2] / c.rms_error[2]);
        scores[f].within_1[k].push_back(c.within_1[2]);
        scores[f].within_2[k].push_back(c.within_2[2]);
      }
      std::printf(
          "bench=depth_response case=%s set=%d gain_w=%.3f gain_w_response=%.3f bias_w=%.3f bias_w_response=%.3f "
          "rms_w=%.3f rms_w_response=%.3f rms_u=%.3f rms_v=%.3f\n",
          flows[f].first, set, scores[f].gain[0].back(), scores[f].gain[1].back(), scores[f].bias[0].back(),
          scores[f].bias[1].back(), scores[f].rms[0].back(), scores[f].rms[1].back(), scores[f].rms_u.back(),
          scores[f].rms_v.back());
      std::fflush(stdout);
    }
  }
  // Per flow: the mean and its standard error over the sets, without and with the response.
  for (std::size_t f = 0; f < std::size(flows); ++f) {
    const MeanError u = mean_error(scores[f].rms_u), v = mean_error(scores[f].rms_v);
    std::printf(
        "bench=depth_response case=%s summary=1 sets=%d rms_u=%.3f rms_u_error=%.3f rms_v=%.3f rms_v_error=%.3f",
        flows[f].first, sets, u.mean, u.error, v.mean, v.error);
    for (int k = 0; k < 2; ++k) {
      const char* suffix = k ? "_response" : "";
      const MeanError g = mean_error(scores[f].gain[k]), b = mean_error(scores[f].bias[k]),
                      r = mean_error(scores[f].rms[k]), s = mean_error(scores[f].sigma_ratio[k]),
                      w1 = mean_error(scores[f].within_1[k]), w2 = mean_error(scores[f].within_2[k]);
      std::printf(
          " gain_w%s=%.3f gain_w%s_error=%.3f bias_w%s=%.3f bias_w%s_error=%.3f rms_w%s=%.3f rms_w%s_error=%.3f"
          " sigma_ratio_w%s=%.3f within_1sigma_w%s=%.3f within_2sigma_w%s=%.3f",
          suffix, g.mean, suffix, g.error, suffix, b.mean, suffix, b.error, suffix, r.mean, suffix, r.error, suffix,
          s.mean, suffix, w1.mean, suffix, w2.mean);
    }
    std::printf("\n");
  }
  return 0;
}
