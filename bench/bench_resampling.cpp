// Cost of resampling raw images onto an axis-aligned lattice (lightfield::LatticeResampler) against
// the rotation of the array, on the small camera and the paper's: setup once per run, then per frame.
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <numbers>
#include <string>
#include <vector>

#include "core/calib/nominal_calibration.hpp"
#include "core/lightfield/lattice_resampling.hpp"
#include "core/optics/camera_file.hpp"
#include "core/recon/weights.hpp"
#include "core/sim/render.hpp"

using namespace plenopiv;

namespace {

double seconds_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

}  // namespace

int main() {
  for (const std::string name : {"camera-small", "camera-fahringer2015"}) {
    const auto camera =
        optics::load_camera_file(std::string(PLENOPIV_SOURCE_DIR) + "/systemd/config/" + name + ".yaml");
    for (double degrees : {0.05, 0.3, 1.0, 2.0}) {
      optics::Lattice l = optics::Lattice::nominal(camera);
      l.rotation_rad = degrees * std::numbers::pi / 180;
      const auto array = sim::jittered_array(l, 0.001, 5);
      const ImageF white = calib::geometric_white_image(camera, array);
      auto t0 = std::chrono::steady_clock::now();
      const lightfield::LatticeResampler r(camera, array, white);
      const double setup = seconds_since(t0);
      const ImageF raw = white;  // any sensor-sized image: the cost does not depend on the values
      ImageF out;
      std::vector<double> times;
      for (int k = 0; k < 5; ++k) {
        t0 = std::chrono::steady_clock::now();
        r.resample(raw, out);
        times.push_back(seconds_since(t0));
      }
      std::sort(times.begin(), times.end());
      std::printf(
          "bench=resampling camera=%s rotation_deg=%.2f max_departure_px=%.1f setup_s=%.3f frame_median_s=%.4f\n",
          name.c_str(), degrees, recon::separable_lattice(array).max_departure_mm / camera.sensor().pixel_pitch_mm,
          setup, times[2]);
    }
  }
}
