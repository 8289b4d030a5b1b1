// Calibration at paper size (4904 x 3280, 289 x 193 lenses): spot detection, the full lattice fit
// and the white correction, at 1 and 2 threads, side by side on the same rendered images.
#include <sys/resource.h>
#include <tbb/global_control.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <functional>
#include <string>
#include <vector>

#include "core/calib/calibration.hpp"
#include "core/optics/camera_file.hpp"
#include "tests/calib/spot_render.hpp"

using namespace plenopiv;

namespace {

// Process CPU seconds (user + system): on a shared machine wall time includes waiting for a core.
double cpu_seconds() {
  rusage u{};
  getrusage(RUSAGE_SELF, &u);
  return u.ru_utime.tv_sec + u.ru_stime.tv_sec + 1e-6 * (u.ru_utime.tv_usec + u.ru_stime.tv_usec);
}

struct Timing {
  double wall_s;
  double cpu_s;
};

// Median wall time over `repeats` runs, and the CPU time of that run.
Timing median_seconds(int repeats, const std::function<void()>& work) {
  std::vector<Timing> t;
  for (int r = 0; r < repeats; ++r) {
    const auto start = std::chrono::steady_clock::now();
    const double cpu0 = cpu_seconds();
    work();
    t.push_back(
        {std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count(), cpu_seconds() - cpu0});
  }
  std::sort(t.begin(), t.end(), [](const Timing& a, const Timing& b) { return a.wall_s < b.wall_s; });
  return t[t.size() / 2];
}

}  // namespace

int main(int argc, char** argv) {
  const std::string camera_file = argc > 1 ? argv[1] : PLENOPIV_SOURCE_DIR "/systemd/config/camera-fahringer2015.yaml";
  const int repeats = argc > 2 ? std::max(1, std::atoi(argv[2])) : 3;
  const optics::CameraModel camera = optics::load_camera_file(camera_file);
  testing_support::SpotScene scene;
  scene.rotation_deg = 0.5;
  scene.offset_x_mm = 0.011;
  scene.offset_y_mm = -0.007;
  scene.jitter_mm = 0.001;
  scene.noise_sigma = 8;
  scene.vignetting = 0.3;
  scene.hot_pixels = 2000;
  const auto spots = testing_support::render_calibration(camera, scene);
  const ImageF white = testing_support::render_white(camera, spots, scene, 0.9);
  std::printf("# %s: %d x %d pixels, %d lenses\n", camera_file.c_str(), camera.sensor().width_px,
              camera.sensor().height_px, camera.lens_count());

  double base_total = 0;
  for (int threads : {1, 2}) {
    tbb::global_control limit(tbb::global_control::max_allowed_parallelism, threads);
    calib::SpotOptions so;
    so.max_area_px = 140;
    const Timing t_spots = median_seconds(repeats, [&] { calib::find_spots(spots.image, so); });
    calib::Calibration cal;
    const Timing t_fit = median_seconds(repeats, [&] { cal = calib::calibrate(camera, spots.image); });
    const Timing t_white = median_seconds(repeats, [&] { calib::make_white_correction(cal, white, scene.background); });
    const double total = t_fit.wall_s + t_white.wall_s;
    if (threads == 1) base_total = total;
    std::printf("bench=calib stage=find_spots threads=%d median_s=%.3f cpu_s=%.3f\n", threads, t_spots.wall_s,
                t_spots.cpu_s);
    std::printf(
        "bench=calib stage=calibrate threads=%d median_s=%.3f cpu_s=%.3f lenses_measured=%d rms_residual_px=%.4f\n",
        threads, t_fit.wall_s, t_fit.cpu_s, cal.lenses_measured, cal.rms_residual_px);
    std::printf("bench=calib stage=white_correction threads=%d median_s=%.3f cpu_s=%.3f\n", threads, t_white.wall_s,
                t_white.cpu_s);
    std::printf("bench=calib stage=total threads=%d median_s=%.3f cpu_s=%.3f ratio_to_1_thread=%.2f\n", threads, total,
                t_fit.cpu_s + t_white.cpu_s, total / base_total);
  }
  return 0;
}
