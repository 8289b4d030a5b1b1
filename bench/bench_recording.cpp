// What recording a paper-scale pair costs the daemon's machine, with the lanes left out: the replay
// camera delivers decoded frames (as a camera's driver hands them over), the run folder writer
// writes both as TIFF, the frame check scans them, and the pair is let go, its buffers freed
// ("fresh") or given back to the camera's frame pool ("pooled", as plenopivd does). The camera plays
// at RATE_HZ, free-running; the run folder is on DATA_DIR (default: the temporary folder's disk),
// which the writer reaches past the page cache where its file system allows (write=direct).
//   bench_recording [PAIRS] [REPEATS] [RATE_HZ] [DATA_DIR]   (default 100 pairs, 3 repeats, 10 Hz)
// Where DATA_DIR has no room for a variant's frames, each pair's are deleted once the next is
// recorded (frames_deleted=during). Per variant: medians over the repeats of wall and CPU seconds
// per pair (wall: 1 / RATE_HZ while the recording keeps up) and minor page faults per pair, and the
// pool's reuse. The variants alternate, so drift in the machine's load hits both.
#include <sys/resource.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <string>
#include <vector>

#include "bench/bench_support.hpp"
#include "bench/replay_recording.hpp"
#include "core/io/direct_writer.hpp"
#include "core/optics/camera_file.hpp"
#include "core/process/frame_check.hpp"
#include "drivers/camera/frame_pool.hpp"
#include "drivers/replay/replay_camera.hpp"
#include "proto/run_folder.hpp"

using namespace plenopiv;
namespace fs = std::filesystem;

namespace {

struct Figures {
  double wall_s_per_pair = 0, cpu_s_per_pair = 0, faults_per_pair = 0, reused = 0;
};

long minor_faults() {
  rusage u{};
  getrusage(RUSAGE_SELF, &u);
  return u.ru_minflt;
}

// `pairs` pairs from `camera` into a new run folder under `data`, each let go at once; each pair's
// frames deleted once the next is recorded if `delete_during` (a data folder without room for them).
Figures record(drivers::Camera& camera, const fs::path& data, const std::string& run_id, int pairs, bool pooled,
               bool delete_during) {
  run_folder::Writer::Setup setup;
  setup.data_dir = data;
  setup.run_id = run_id;
  setup.camera_uri = camera.info().uri;
  setup.trigger_uri = "software";
  setup.camera_model = camera.info().model;
  setup.nominal_dt_s = 100e-6;
  run_folder::Writer writer(setup);
  const drivers::FramePool::Counts before = camera.frame_pool()->counts();
  const double wall0 = bench::now_s(), cpu0 = bench::cpu_seconds();
  const long faults0 = minor_faults();
  for (int i = 0; i < pairs; ++i) {
    std::optional<drivers::FramePair> pair = camera.next_pair(std::chrono::seconds(5));
    if (!pair) {
      std::fprintf(stderr, "bench_recording: pair %d never came\n", i);
      std::exit(1);
    }
    run_folder::PairRecord r;
    r.pair_index = std::uint64_t(i);
    r.trigger_index = pair->trigger_index;
    r.frame_a = &pair->a.image;
    r.frame_b = &pair->b.image;
    r.frame_id_a = pair->a.frame_id;
    r.frame_id_b = pair->b.frame_id;
    // The frame check as plenopivd makes it: its statistics gathered while the frames are written.
    process::FrameRange range_a, range_b;
    r.visit_rows_a = [&range_a](std::span<const std::uint16_t> rows) { range_a.add(rows); };
    r.visit_rows_b = [&range_b](std::span<const std::uint16_t> rows) { range_b.add(rows); };
    writer.record_pair(r);
    (void)process::frame_problem(pair->a.image.pixels, pair->a.bit_depth, range_a);
    (void)process::frame_problem(pair->b.image.pixels, pair->b.bit_depth, range_b);
    (void)drivers::share_pair(std::move(*pair), pooled ? camera.frame_pool() : nullptr);
    // The folder holds the last pair only: 100 paper-scale pairs are 6 GB. A deletion is timed with
    // the recording and, on a disk mounted with online discard, trims its blocks at the journal's
    // commit, which stalls the writes: where there is room the frames stay until the run's end.
    if (delete_during && i > 0) {
      char name[64];
      for (const char* k : {"A", "B"}) {
        std::snprintf(name, sizeof name, "pair-%06d-%s.tif", i - 1, k);
        fs::remove(writer.dir() / "frames" / name);
      }
    }
  }
  Figures f;
  f.wall_s_per_pair = (bench::now_s() - wall0) / pairs;
  f.cpu_s_per_pair = (bench::cpu_seconds() - cpu0) / pairs;
  f.faults_per_pair = double(minor_faults() - faults0) / pairs;
  const drivers::FramePool::Counts after = camera.frame_pool()->counts();
  f.reused = double(after.reused - before.reused) / double(std::max<std::uint64_t>(1, after.taken - before.taken));
  writer.close("complete", 0, 0);
  fs::remove_all(writer.dir());
  ::sync();  // the deletion's trims done before the next variant records
  return f;
}

}  // namespace

int main(int argc, char** argv) {
  const int pairs = argc > 1 ? std::atoi(argv[1]) : 100;
  const int repeats = argc > 2 ? std::atoi(argv[2]) : 3;
  const double rate_hz = argc > 3 ? std::atof(argv[3]) : 10.0;
  const fs::path data = argc > 4 ? fs::path(argv[4]) : fs::temp_directory_path() / "plenopiv-bench-recording";
  if (pairs < 2 || repeats < 1 || !(rate_hz > 0)) {
    std::fprintf(stderr, "usage: bench_recording [PAIRS >= 2] [REPEATS >= 1] [RATE_HZ > 0] [DATA_DIR]\n");
    return 2;
  }
  const fs::path camera_file = fs::path(PLENOPIV_SOURCE_DIR) / "systemd/config/camera-fahringer2015.yaml";
  const optics::CameraModel camera_model = optics::load_camera_file(camera_file);
  auto camera = drivers::open_replay_camera(
      drivers::DeviceUri::parse("replay://paper?loop=1&buffer_mb=1024&rate_hz=" + std::to_string(rate_hz)),
      {bench::write_paper_replay_recording(camera_model), camera_file});
  camera->configure(drivers::CameraSettings{});
  camera->arm(drivers::DoubleExposureSettings{drivers::TriggerSource::Software, 0.0});  // free-running
  camera->start();
  fs::remove_all(data);
  fs::create_directories(data);
  const char* write_mode = io::direct_write_mode(data) == io::WriteMode::direct ? "direct" : "buffered";
  // One variant's frames, with a tenth to spare.
  const bool delete_during = double(fs::space(data).available) < 1.1 * bench::pair_bytes(camera_model) * pairs;
  (void)record(*camera, data, "warm-up", 4, true, false);  // decoding the recording, the first frames' pages

  std::vector<Figures> fresh, pooled;
  for (int r = 0; r < repeats; ++r) {
    fresh.push_back(record(*camera, data, "fresh-" + std::to_string(r), pairs, false, delete_during));
    pooled.push_back(record(*camera, data, "pooled-" + std::to_string(r), pairs, true, delete_during));
  }
  camera->stop();
  fs::remove_all(data);

  auto med = [](const std::vector<Figures>& v, double Figures::*field) {
    std::vector<double> x;
    for (const Figures& f : v) x.push_back(f.*field);
    return bench::median(x);
  };
  const char* names[] = {"fresh", "pooled"};
  const std::vector<Figures>* runs[] = {&fresh, &pooled};
  for (int k = 0; k < 2; ++k) {
    const std::vector<Figures>& v = *runs[k];
    std::printf(
        "bench=recording variant=%s pairs=%d repeats=%d rate_hz=%.1f data_dir=%s write=%s mb_per_pair=%.1f "
        "wall_s_per_pair=%.4f cpu_s_per_pair=%.4f cores=%.2f faults_per_pair=%.0f buffers_reused=%.2f "
        "frames_deleted=%s\n",
        names[k], pairs, repeats, rate_hz, data.c_str(), write_mode,
        bench::pair_bytes(camera_model) / (1024.0 * 1024.0), med(v, &Figures::wall_s_per_pair),
        med(v, &Figures::cpu_s_per_pair), rate_hz * med(v, &Figures::cpu_s_per_pair), med(v, &Figures::faults_per_pair),
        med(v, &Figures::reused), delete_during ? "during" : "after");
  }
  std::printf("bench=recording_ratio pooled_over_fresh_cpu=%.2f\n",
              med(pooled, &Figures::cpu_s_per_pair) / med(fresh, &Figures::cpu_s_per_pair));
  return 0;
}
