// The daemon's two lanes under a laser: ray-traced pairs (camera-small) replayed at rate_hz through
// a whole in-process run (sim trigger, replay camera, recorder, real processing), the live lane
// alone against the live lane with the full settings' quality lane behind it, with the processing
// threads at plenopivd's default niceness and at the recording's own (processing_nice 0).
#include <sys/resource.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>
#include <thread>

#include "bench/bench_support.hpp"
#include "bench/replay_recording.hpp"
#include "core/optics/camera_file.hpp"
#include "daemon/daemon_config.hpp"
#include "daemon/processing.hpp"
#include "daemon/run.hpp"
#include "drivers/replay/replay_camera.hpp"

using namespace plenopiv;
namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

using bench::rss_gb;

int main(int argc, char** argv) {
  const int pairs = argc > 1 ? std::atoi(argv[1]) : 200;
  const double rate_hz = argc > 2 ? std::atof(argv[2]) : 10.0;
  const fs::path camera_file = fs::path(PLENOPIV_SOURCE_DIR) / "systemd/config/camera-small.yaml";
  const optics::CameraModel camera = optics::load_camera_file(camera_file);
  const fs::path root = fs::temp_directory_path() / "plenopiv-bench-lanes";
  bench::write_replay_recording(root / "replay" / "small", camera, 8);
  drivers::register_replay_camera(drivers::CameraRegistry::instance(), {root / "replay", camera_file});

  // Full settings: the shipped run.yaml's box at 0.0625 mm and 10 iterations; live tier: 0.25 mm,
  // 3 iterations, one pass.
  const std::string spec =
      "dt_s: 0.001\nvolume: {x_mm: [-2, 2], y_mm: [-2, 2], z_mm: [-1, 1], voxel_mm: 0.0625}\n"
      "reconstruction: {iterations: 10, mu: 1}\n"
      "correlation: {passes: [{window: 32, overlap_percent: 50}, {window: 16, overlap_percent: 50}]}\n"
      "live: {volume: {voxel_mm: 0.25}, reconstruction: {iterations: 3}, "
      "correlation: {passes: [{window: 8, overlap_percent: 50}]}}\n";
  struct Variant {
    const char* name;
    const char* lanes;
    int nice;
  };
  const int nice = daemon::DaemonConfig{}.processing_nice;
  const std::vector<Variant> variants{{"live_only", "quality: off\n", nice},
                                      {"live_and_quality", "quality: newest\n", nice},
                                      {"live_and_quality_nice_0", "quality: newest\n", 0}};
  const daemon::ProcessFactory processing = daemon::plenoptic_processing(camera);
  for (const auto& [name, lanes, processing_nice] : variants) {
    const fs::path data = root / "data";
    fs::remove_all(data);
    daemon::RunStateMachine state;
    const daemon::RunEnvironment env =
        bench::replay_run_environment(data, camera_file, state, processing, processing_nice);
    const daemon::RunConfig config = daemon::parse_run_config(
        "pairs: " + std::to_string(pairs) + "\nrate_hz: " + std::to_string(rate_hz) + "\n" + lanes + spec, name);
    state.start(name);
    const auto t0 = Clock::now();
    double rss_min = 1e9, rss_max = 0;
    double acquiring_at = 0;
    std::uint64_t samples = 0;
    {
      daemon::Run run(config, name, env);
      while (!run.finished()) {
        std::this_thread::sleep_for(std::chrono::milliseconds(500));
        const double r = rss_gb();
        rss_min = std::min(rss_min, r);
        rss_max = std::max(rss_max, r);
        ++samples;
        if (acquiring_at == 0 && state.state() == daemon::RunState::Acquiring)
          acquiring_at = std::chrono::duration<double>(Clock::now() - t0).count();
      }
      msg::Status s;
      run.fill_status(s);
      const double wall = std::chrono::duration<double>(Clock::now() - t0).count() - acquiring_at;
      const double acquire_s = double(pairs) / rate_hz;
      msg::LaneCounters live, quality;
      for (const msg::LaneCounters& l : s.lanes()) (l.name() == "live" ? live : quality) = l;
      std::printf(
          "bench=lanes variant=%s processing_nice=%d pairs=%d rate_hz=%.1f setup_s=%.1f run_s=%.1f recorded=%llu "
          "frames_lost=%llu "
          "live_fields=%llu live_fields_per_s=%.2f live_dropped=%llu live_mean_s=%.3f quality_fields=%llu "
          "quality_fields_per_s=%.3f quality_dropped=%llu quality_mean_s=%.2f rss_min_gb=%.2f rss_max_gb=%.2f "
          "rss_samples=%llu state=%s\n",
          name, processing_nice, pairs, rate_hz, acquiring_at, wall,
          static_cast<unsigned long long>(s.pairs_recorded()), static_cast<unsigned long long>(s.frames_lost()),
          static_cast<unsigned long long>(live.processed()), double(live.processed()) / acquire_s,
          static_cast<unsigned long long>(live.dropped()), live.mean_time_s(),
          static_cast<unsigned long long>(quality.processed()), double(quality.processed()) / acquire_s,
          static_cast<unsigned long long>(quality.dropped()), quality.mean_time_s(), rss_min, rss_max,
          static_cast<unsigned long long>(samples), daemon::to_string(state.state()));
      std::fflush(stdout);
    }
  }
  fs::remove_all(root / "data");
  return 0;
}
