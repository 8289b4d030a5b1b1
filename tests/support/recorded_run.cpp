// Short live runs recorded in-process for tests that reprocess run folders.
#include "tests/support/recorded_run.hpp"

#include <gtest/gtest.h>

#include <chrono>
#include <thread>

#include "core/optics/camera_file.hpp"
#include "daemon/processing.hpp"
#include "drivers/camera/camera_registry.hpp"
#include "drivers/sim/sim_camera.hpp"

namespace plenopiv::testing_support {
namespace fs = std::filesystem;

const std::string& small_camera_file() {
  static const std::string file = std::string(PLENOPIV_SOURCE_DIR) + "/systemd/config/camera-small.yaml";
  return file;
}

daemon::RunConfig small_run_config(int pairs) {
  return daemon::parse_run_config("pairs: " + std::to_string(pairs) +
                                      "\nrate_hz: 2\ndt_s: 0.001\nmax_pairs_in_flight: 3\n"
                                      "volume: {x_mm: [-1, 1], y_mm: [-1, 1], z_mm: [-0.5, 0.5], voxel_mm: 0.125}\n"
                                      "reconstruction: {iterations: 2, start: ones, dark_weight_cutoff: 0.99}\n"
                                      "correlation: {passes: [{window: 8, overlap_percent: 50}]}\n",
                                  "run.yaml");
}

std::string small_sim_uri(const std::string& extra) {
  return "sim://?seed=3&ppm=0.2&rays=500&dx_mm=0.25&flow_dt_us=1000" + extra;
}

daemon::RunEnvironment small_run_environment(const fs::path& data, daemon::RunStateMachine& state,
                                             const std::string& camera_uri, const fs::path& calibration_file) {
  drivers::register_sim_camera(drivers::CameraRegistry::instance(), small_camera_file());
  daemon::RunEnvironment env;
  env.data_dir = data;
  env.default_camera_uri = camera_uri;
  env.default_trigger_uri = "sim://";
  env.camera_file = small_camera_file();
  env.calibration_file = calibration_file;
  env.state = &state;
  env.processing = daemon::plenoptic_processing(optics::load_camera_file(small_camera_file()));
  return env;
}

fs::path record_small_run(const fs::path& data, const std::string& camera_uri, const fs::path& calibration_file,
                          int pairs) {
  using namespace std::chrono_literals;
  fs::remove_all(data);
  daemon::RunStateMachine state;
  const daemon::RunEnvironment env = small_run_environment(data, state, camera_uri, calibration_file);
  state.start("r");
  daemon::Run run(small_run_config(pairs), "r", env);
  for (int i = 0; i < 3000 && !run.finished(); ++i) std::this_thread::sleep_for(10ms);
  EXPECT_TRUE(run.finished());
  EXPECT_EQ(state.state(), daemon::RunState::Idle) << state.error();
  return run.dir();
}

}  // namespace plenopiv::testing_support
