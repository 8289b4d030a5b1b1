// A replay folder of ray-traced camera-small pairs and the environment of a whole in-process run
// that plays it through `replay://`, shared by bench_lanes and bench_soak.
#pragma once

#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <string>

#include "core/io/tiff.hpp"
#include "core/optics/camera_model.hpp"
#include "core/optics/microlens_array.hpp"
#include "core/sim/particles.hpp"
#include "core/sim/render.hpp"
#include "daemon/run.hpp"

namespace plenopiv::bench {

// The scene of a replay recording: `particles` in `box`, `rays_per_particle` each.
struct ReplayScene {
  sim::Box box{{-2, -2, -1}, {2, 2, 1}};
  std::size_t particles = 60;
  std::size_t rays_per_particle = 100000;
};

// `count` pairs in `dir` as frame-<k>.tif (kept when already there): by default 60 particles in a
// 4 x 4 x 2 mm box (as bench_daemon); displaced 0.25 mm along x between exposures.
inline void write_replay_recording(const std::filesystem::path& dir, const optics::CameraModel& camera, int count,
                                   const ReplayScene& scene = {}) {
  namespace fs = std::filesystem;
  fs::create_directories(dir);
  const auto lenses = optics::MicrolensArray::from_lattice(optics::Lattice::nominal(camera));
  sim::RenderOptions render;
  render.rays_per_particle = scene.rays_per_particle;
  for (int i = 0; i < count; ++i) {
    char a_name[32], b_name[32];
    std::snprintf(a_name, sizeof a_name, "frame-%04d.tif", 2 * i);
    std::snprintf(b_name, sizeof b_name, "frame-%04d.tif", 2 * i + 1);
    if (fs::exists(dir / a_name) && fs::exists(dir / b_name)) continue;
    const auto a = sim::random_particles(scene.box, scene.particles, 100 + std::uint64_t(i));
    auto b = a;
    for (auto& p : b) p[0] += 0.25;
    io::write_tiff(dir / a_name, sim::render(camera, lenses, a, render, 2 * std::uint64_t(i)).image, false);
    io::write_tiff(dir / b_name, sim::render(camera, lenses, b, render, 2 * std::uint64_t(i) + 1).image, false);
  }
}

// The paper-scale replay recording bench_lanes and bench_recording share: 4 pairs of run-paper.yaml's
// box at 0.5 particles per microlens (as bench_e2e's full case), in <tmp>/plenopiv-bench-lanes/
// replay/paper (kept between runs). Returns the replay folder (a ReplaySource's replay_dir).
inline std::filesystem::path write_paper_replay_recording(const optics::CameraModel& camera) {
  const std::filesystem::path replay = std::filesystem::temp_directory_path() / "plenopiv-bench-lanes" / "replay";
  ReplayScene scene;
  scene.box = {{-18.75, -12.5, -12.5}, {18.75, 12.5, 12.5}};
  scene.particles = sim::particle_count_from_ppm(camera, scene.box, 0.5);
  scene.rays_per_particle = 5000;
  write_replay_recording(replay / "paper", camera, 4, scene);
  return replay;
}

// The bytes of one pair's 16-bit frames on `camera`'s sensor (its TIFFs hold a little more).
inline double pair_bytes(const optics::CameraModel& camera) {
  return 2.0 * double(camera.sensor().width_px) * double(camera.sensor().height_px) * 2.0;
}

// A run's environment: data in `data`, the replay camera `replay://<source>` (default: the folder
// `small`, looped), the sim trigger, `camera_file`, `processing` with its threads at `nice`.
inline daemon::RunEnvironment replay_run_environment(const std::filesystem::path& data,
                                                     const std::filesystem::path& camera_file,
                                                     daemon::RunStateMachine& state,
                                                     const daemon::ProcessFactory& processing, int nice,
                                                     const std::string& source = "small?loop=1") {
  daemon::RunEnvironment env;
  env.data_dir = data;
  env.default_camera_uri = "replay://" + source;
  env.default_trigger_uri = "sim://";
  env.camera_file = camera_file;
  env.state = &state;
  env.processing = processing;
  env.processing_nice = nice;
  return env;
}

}  // namespace plenopiv::bench
