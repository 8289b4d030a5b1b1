// Short live runs recorded in-process (simulated trigger and camera on the small camera, the
// plenoptic stage) into a folder, for tests that reprocess run folders.
#pragma once

#include <filesystem>
#include <string>

#include "daemon/run.hpp"
#include "daemon/run_config.hpp"

namespace plenopiv::testing_support {

// systemd/config/camera-small.yaml.
const std::string& small_camera_file();

// `pairs` pairs at 2 Hz, dt 1 ms, a 2 x 2 x 1 mm volume of 0.125 mm voxels, 2 MART iterations, one
// 8-voxel correlation pass: seconds per run on two cores.
daemon::RunConfig small_run_config(int pairs = 3);

// The simulated camera at 0.2 ppm moving its particles 0.25 mm along x in 1 ms; `extra` adds URI
// parameters ("&array_rotation_rad=0.005").
std::string small_sim_uri(const std::string& extra = "");

// What a daemon gives its runs: the folder `data`, the simulated camera and trigger, the small
// camera file, `calibration_file` (empty: nominal) and the plenoptic processing.
daemon::RunEnvironment small_run_environment(const std::filesystem::path& data, daemon::RunStateMachine& state,
                                             const std::string& camera_uri,
                                             const std::filesystem::path& calibration_file);

// A whole live run of `pairs` pairs into `data` (emptied first); the run folder. Test failures
// (not exceptions) when it does not finish or ends in an error.
std::filesystem::path record_small_run(const std::filesystem::path& data, const std::string& camera_uri,
                                       const std::filesystem::path& calibration_file = {}, int pairs = 3);

}  // namespace plenopiv::testing_support
