// The daemon's two lanes under a laser: ray-traced pairs replayed at rate_hz through a whole
// in-process run (sim trigger, replay camera, recorder, real processing).
//   bench_lanes [PAIRS] [RATE_HZ]: camera-small; the live lane alone against the live lane with the
//       full settings' quality lane behind it, with the processing threads at plenopivd's default
//       niceness and at the recording's own (processing_nice 0).
//   bench_lanes paper [PAIRS] [RATE_HZ] [DATA_DIR]: the shipped run-paper.yaml (its live tier, the
//       quality lane behind it) on paper-scale frames (default 600 pairs at 10 Hz), sampled each
//       second (bench=lanes_sample lines; bench/plot_lanes.py draws them). The replay camera
//       preloads its frames (buffer_mb), as a camera delivers them decoded. 64 MB a pair at 10 Hz is
//       640 MB/s onto DATA_DIR (default: the temporary folder's disk, written past the page cache
//       where it allows). Where DATA_DIR has room for the run's raw frames (38 GB), they stay until
//       the run ends, as a recording keeps them; where it has not, they are deleted once recorded
//       (frames_deleted=during), a stand-in that costs the file system what a recording never does:
//       on a disk mounted with online discard each deletion trims its blocks at the journal's commit,
//       which stalls the recorder's own writes.
#include <sys/resource.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>
#include <thread>
#include <utility>

#include <yaml-cpp/yaml.h>

#include "bench/bench_support.hpp"
#include "bench/replay_recording.hpp"
#include "core/optics/camera_file.hpp"
#include "core/sim/particles.hpp"
#include "daemon/daemon_config.hpp"
#include "daemon/processing.hpp"
#include "daemon/run.hpp"
#include "drivers/replay/replay_camera.hpp"

using namespace plenopiv;
namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

using bench::rss_gb;

namespace {

// Deletes the raw frames of pairs recorded before `keep_from` (frames/pair-NNNNNN-A.tif, -B.tif)
// in every run folder under `data`; the lanes hold their pairs in memory.
void delete_recorded_frames(const fs::path& data, std::uint64_t keep_from) {
  std::error_code ec;
  for (const auto& run : fs::directory_iterator(data, ec)) {
    for (const auto& f : fs::directory_iterator(run.path() / "frames", ec)) {
      const std::string name = f.path().filename().string();
      if (name.rfind("pair-", 0) == 0 && std::strtoull(name.c_str() + 5, nullptr, 10) < keep_from)
        fs::remove(f.path(), ec);
    }
  }
}

// One variant's result line: the run's end status, per lane; rates over `acquire_s`.
struct RunFigures {
  double setup_s = 0, run_s = 0, acquire_s = 1, rss_min_gb = 0, rss_max_gb = 0;
};
// frames_deleted: "after" the run, or "during" it once recorded (a data folder without room for them).
void print_result(const char* variant, int nice, int pairs, double rate_hz, const RunFigures& f, const msg::Status& s,
                  daemon::RunState state, const char* frames_deleted) {
  msg::LaneCounters live, quality;
  for (const msg::LaneCounters& l : s.lanes()) (l.name() == "live" ? live : quality) = l;
  std::printf(
      "bench=lanes variant=%s processing_nice=%d pairs=%d rate_hz=%.1f setup_s=%.1f run_s=%.1f recorded=%llu "
      "frames_lost=%llu live_fields=%llu live_fields_per_s=%.2f live_dropped=%llu live_mean_s=%.3f "
      "quality_fields=%llu quality_fields_per_s=%.3f quality_dropped=%llu quality_mean_s=%.2f rss_min_gb=%.2f "
      "rss_max_gb=%.2f state=%s frames_deleted=%s\n",
      variant, nice, pairs, rate_hz, f.setup_s, f.run_s, static_cast<unsigned long long>(s.pairs_recorded()),
      static_cast<unsigned long long>(s.frames_lost()), static_cast<unsigned long long>(live.processed()),
      double(live.processed()) / f.acquire_s, static_cast<unsigned long long>(live.dropped()), live.mean_time_s(),
      static_cast<unsigned long long>(quality.processed()), double(quality.processed()) / f.acquire_s,
      static_cast<unsigned long long>(quality.dropped()), quality.mean_time_s(), f.rss_min_gb, f.rss_max_gb,
      daemon::to_string(state), frames_deleted);
  std::fflush(stdout);
}

int paper_lanes(int argc, char** argv) {
  const int pairs = argc > 1 ? std::atoi(argv[1]) : 600;
  const double rate_hz = argc > 2 ? std::atof(argv[2]) : 10.0;
  const fs::path data = argc > 3 ? fs::path(argv[3]) : fs::temp_directory_path() / "plenopiv-bench-lanes-paper";
  const fs::path config_dir = fs::path(PLENOPIV_SOURCE_DIR) / "systemd/config";
  const fs::path camera_file = config_dir / "camera-fahringer2015.yaml";
  const optics::CameraModel camera = optics::load_camera_file(camera_file);
  drivers::register_replay_camera(drivers::CameraRegistry::instance(),
                                  {bench::write_paper_replay_recording(camera), camera_file});

  const daemon::ProcessFactory processing = daemon::plenoptic_processing(camera);
  const int nice = daemon::DaemonConfig{}.processing_nice;
  // The shipped config without its quality lane, then as shipped.
  for (const auto& [name, quality] : {std::pair{"paper_live_only", "off"}, std::pair{"paper_run_paper_yaml", ""}}) {
    YAML::Node run_yaml = YAML::LoadFile((config_dir / "run-paper.yaml").string());
    // Until stopped, stopped here after `pairs`: a bounded run is refused where its raw frames would
    // not fit DATA_DIR, and the deletion below is what makes them fit.
    run_yaml["pairs"] = 0;
    run_yaml["rate_hz"] = rate_hz;
    if (*quality) run_yaml["quality"] = quality;
    const daemon::RunConfig config = daemon::parse_run_config(YAML::Dump(run_yaml), "run-paper.yaml");
    fs::remove_all(data);
    ::sync();  // the last variant's trims done before this one records
    fs::create_directories(data);
    // The run's raw frames, and 10 s of pairs past the count (the stop comes at the next sample), with
    // a tenth to spare.
    const bool delete_during =
        double(fs::space(data).available) < 1.1 * bench::pair_bytes(camera) * (pairs + 10 * rate_hz);
    daemon::RunStateMachine state;
    const daemon::RunEnvironment env =
        bench::replay_run_environment(data, camera_file, state, processing, nice, "paper?loop=1&buffer_mb=1024");
    state.start(name);
    const auto t0 = Clock::now();
    double acquiring_at = 0, stopped_at = 0, rss_min = 1e9, rss_max = 0;
    auto now = [&] { return std::chrono::duration<double>(Clock::now() - t0).count(); };
    daemon::Run run(config, name, env);
    msg::Status s;
    while (!run.finished()) {
      std::this_thread::sleep_for(std::chrono::seconds(1));
      s.Clear();
      run.fill_status(s);
      if (acquiring_at == 0 && state.state() == daemon::RunState::Acquiring) acquiring_at = now();
      if (acquiring_at == 0) continue;
      if (delete_during && s.pairs_recorded() > 2) delete_recorded_frames(data, s.pairs_recorded() - 2);
      if (stopped_at == 0 && s.pairs_recorded() >= std::uint64_t(pairs)) {
        run.request_stop();
        stopped_at = now();
      }
      const double rss = rss_gb();
      rss_min = std::min(rss_min, rss);
      rss_max = std::max(rss_max, rss);
      std::uint64_t fields[2] = {0, 0};
      for (const msg::LaneCounters& l : s.lanes()) fields[l.name() == "live" ? 0 : 1] = l.processed();
      std::printf(
          "bench=lanes_sample variant=%s t_s=%.0f recorded=%llu frames_lost=%llu live_fields=%llu "
          "quality_fields=%llu rss_gb=%.3f\n",
          name, now() - acquiring_at, static_cast<unsigned long long>(s.pairs_recorded()),
          static_cast<unsigned long long>(s.frames_lost()), static_cast<unsigned long long>(fields[0]),
          static_cast<unsigned long long>(fields[1]), rss);
      std::fflush(stdout);
    }
    s.Clear();
    run.fill_status(s);
    const double acquire_s = (stopped_at > 0 ? stopped_at : now()) - acquiring_at;
    print_result(name, nice, pairs, rate_hz, {acquiring_at, acquire_s, acquire_s, rss_min, rss_max}, s, state.state(),
                 delete_during ? "during" : "after");
  }
  fs::remove_all(data);
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc > 1 && std::string(argv[1]) == "paper") return paper_lanes(argc - 1, argv + 1);
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
    {
      daemon::Run run(config, name, env);
      while (!run.finished()) {
        std::this_thread::sleep_for(std::chrono::milliseconds(500));
        const double r = rss_gb();
        rss_min = std::min(rss_min, r);
        rss_max = std::max(rss_max, r);
        if (acquiring_at == 0 && state.state() == daemon::RunState::Acquiring)
          acquiring_at = std::chrono::duration<double>(Clock::now() - t0).count();
      }
      msg::Status s;
      run.fill_status(s);
      const double wall = std::chrono::duration<double>(Clock::now() - t0).count() - acquiring_at;
      print_result(name, processing_nice, pairs, rate_hz,
                   {acquiring_at, wall, double(pairs) / rate_hz, rss_min, rss_max}, s, state.state(), "after");
    }
  }
  fs::remove_all(root / "data");
  return 0;
}
