// The soak: a long in-process run (sim trigger, replay camera of ray-traced camera-small pairs,
// recorder, the live lane) with the process's memory, file descriptors and threads sampled once
// a second, and the recording's pace: all should stay flat, and no raw frame be lost.
//   bench_soak [pairs=10000] [rate_hz=15] [data folder=/tmp/plenopiv-bench-soak]
// Writes pairs x 2.9 MB of frames into the data folder (29 GB for 10 000 pairs), removed at the end.
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <string>
#include <thread>
#include <vector>

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

namespace {

struct Sample {
  double t_s, rss_gb;
  int fds, threads;
  std::uint64_t recorded, lost, fields;
};

// The median of `field` over the samples in [from, to) of the run (fractions of the samples).
template <typename F>
double median_over(const std::vector<Sample>& s, double from, double to, F field) {
  std::vector<double> v;
  const auto a = std::size_t(from * double(s.size())), b = std::size_t(to * double(s.size()));
  for (std::size_t i = a; i < b && i < s.size(); ++i) v.push_back(field(s[i]));
  return bench::median(v);
}

}  // namespace

int main(int argc, char** argv) {
  const int pairs = argc > 1 ? std::atoi(argv[1]) : 10000;
  const double rate_hz = argc > 2 ? std::atof(argv[2]) : 15.0;
  const fs::path data = argc > 3 ? fs::path(argv[3]) : fs::temp_directory_path() / "plenopiv-bench-soak";
  const fs::path camera_file = fs::path(PLENOPIV_SOURCE_DIR) / "systemd/config/camera-small.yaml";
  const optics::CameraModel camera = optics::load_camera_file(camera_file);
  const fs::path replay = fs::temp_directory_path() / "plenopiv-bench-lanes" / "replay";
  bench::write_replay_recording(replay / "small", camera, 8);
  drivers::register_replay_camera(drivers::CameraRegistry::instance(), {replay, camera_file});

  // bench_lanes's live tier alone: 0.25 mm voxels, 3 iterations, one pass.
  const std::string spec = "pairs: " + std::to_string(pairs) + "\nrate_hz: " + std::to_string(rate_hz) +
                           "\ndt_s: 0.001\nvolume: {x_mm: [-2, 2], y_mm: [-2, 2], z_mm: [-1, 1], voxel_mm: 0.25}\n"
                           "reconstruction: {iterations: 3, mu: 1}\n"
                           "correlation: {passes: [{window: 8, overlap_percent: 50}]}\nquality: off\n";
  fs::remove_all(data);
  daemon::RunStateMachine state;
  const daemon::RunEnvironment env = bench::replay_run_environment(
      data, camera_file, state, daemon::plenoptic_processing(camera), daemon::DaemonConfig{}.processing_nice);
  const daemon::RunConfig config = daemon::parse_run_config(spec, "soak");
  state.start("soak");
  std::vector<Sample> samples;
  msg::Status s;
  double acquiring_at = -1;
  const auto t0 = Clock::now();
  {
    daemon::Run run(config, "soak", env);
    while (!run.finished()) {
      std::this_thread::sleep_for(std::chrono::seconds(1));
      if (state.state() != daemon::RunState::Acquiring && acquiring_at < 0) continue;
      const double t = std::chrono::duration<double>(Clock::now() - t0).count();
      if (acquiring_at < 0) acquiring_at = t;
      s.Clear();
      run.fill_status(s);
      const Sample x{t - acquiring_at,   bench::rss_gb(), bench::open_fd_count(), bench::thread_count(),
                     s.pairs_recorded(), s.frames_lost(), s.pairs_processed()};
      samples.push_back(x);
      std::printf(
          "bench=soak_sample t_s=%.0f recorded=%llu frames_lost=%llu fields=%llu rss_gb=%.3f fds=%d threads=%d\n",
          x.t_s, static_cast<unsigned long long>(x.recorded), static_cast<unsigned long long>(x.lost),
          static_cast<unsigned long long>(x.fields), x.rss_gb, x.fds, x.threads);
      std::fflush(stdout);
    }
    s.Clear();
    run.fill_status(s);
  }
  // The recording's pace early and late in the run (the tenths after the first and before the last
  // twentieth: away from the start and the drain), pairs recorded per second.
  const auto pace = [&](double from, double to) {
    const auto a = std::size_t(from * double(samples.size())), b = std::size_t(to * double(samples.size())) - 1;
    if (samples.size() < 20 || b <= a) return 0.0;
    return double(samples[b].recorded - samples[a].recorded) / (samples[b].t_s - samples[a].t_s);
  };
  const auto rss = [](const Sample& x) { return x.rss_gb; };
  const auto fds = [](const Sample& x) { return double(x.fds); };
  const auto threads = [](const Sample& x) { return double(x.threads); };
  double rss_max = 0;
  int fds_max = 0, threads_max = 0;
  for (const Sample& x : samples) {
    rss_max = std::max(rss_max, x.rss_gb);
    fds_max = std::max(fds_max, x.fds);
    threads_max = std::max(threads_max, x.threads);
  }
  std::printf(
      "bench=soak pairs=%d rate_hz=%.1f run_s=%.0f recorded=%llu frames_lost=%llu live_fields=%llu "
      "pace_first_hz=%.2f pace_last_hz=%.2f rss_first_gb=%.3f rss_last_gb=%.3f rss_max_gb=%.3f fds_first=%.0f "
      "fds_last=%.0f fds_max=%d threads_first=%.0f threads_last=%.0f threads_max=%d samples=%zu state=%s\n",
      pairs, rate_hz, samples.empty() ? 0.0 : samples.back().t_s, static_cast<unsigned long long>(s.pairs_recorded()),
      static_cast<unsigned long long>(s.frames_lost()), static_cast<unsigned long long>(s.pairs_processed()),
      pace(0.05, 0.15), pace(0.85, 0.95), median_over(samples, 0.0, 0.1, rss), median_over(samples, 0.9, 1.0, rss),
      rss_max, median_over(samples, 0.0, 0.1, fds), median_over(samples, 0.9, 1.0, fds), fds_max,
      median_over(samples, 0.0, 0.1, threads), median_over(samples, 0.9, 1.0, threads), threads_max, samples.size(),
      daemon::to_string(state.state()));
  fs::remove_all(data);
  return 0;
}
