// The replay camera at paper scale: recorded 4904 x 3280 px pairs played free-running at rate_hz,
// preloaded against read ahead, taken by a consumer as the daemon's run loop takes them: sustained
// rate, frames lost, queue overflows and resident memory over the run.
#include <sys/resource.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>
#include <thread>
#include <vector>

#include "bench/bench_support.hpp"
#include "core/io/tiff.hpp"
#include "core/optics/camera_file.hpp"
#include "drivers/camera/frame_pool.hpp"
#include "drivers/replay/replay_camera.hpp"

using namespace plenopiv;
namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

namespace {

using bench::rss_gb;

// CPU time of this process so far (all threads: player, read-ahead, consumer), s.
double cpu_s() {
  rusage u{};
  getrusage(RUSAGE_SELF, &u);
  return double(u.ru_utime.tv_sec + u.ru_stime.tv_sec) + double(u.ru_utime.tv_usec + u.ru_stime.tv_usec) * 1e-6;
}

// `pairs` recorded pairs of `width` x `height` px in `dir` (made once; reused when present).
void write_recording(const fs::path& dir, int pairs, int width, int height) {
  fs::create_directories(dir);
  ImageU16 image(width, height);
  for (int k = 0; k < 2 * pairs; ++k) {
    char name[32];
    std::snprintf(name, sizeof name, "frame-%04d.tif", k);
    if (fs::exists(dir / name)) continue;
    for (std::size_t i = 0; i < image.pixels.size(); ++i) image.pixels[i] = std::uint16_t((i * 7919u + k) & 0x0fff);
    io::write_tiff(dir / name, image, false);
  }
}

struct Figures {
  std::uint64_t delivered = 0, frames_lost = 0, overflowed = 0;
  double sustained_hz = 0, open_s = 0, start_s = 0, cpu_ms_per_pair = 0, rss_min_gb = 1e9, rss_max_gb = 0;
};

Figures run(const std::string& uri, const drivers::ReplaySource& source, double seconds) {
  Figures f;
  const auto t0 = Clock::now();
  auto camera = drivers::open_replay_camera(drivers::DeviceUri::parse(uri), source);
  f.open_s = std::chrono::duration<double>(Clock::now() - t0).count();
  camera->configure({});
  camera->arm({drivers::TriggerSource::Software, 0.0});
  std::atomic<bool> done{false};
  std::thread sampler([&] {
    while (!done) {
      const double r = rss_gb();
      f.rss_min_gb = std::min(f.rss_min_gb, r);
      f.rss_max_gb = std::max(f.rss_max_gb, r);
      std::this_thread::sleep_for(std::chrono::milliseconds(200));
    }
  });
  // A recording that fits is decoded in start(): the open answers after reading headers only.
  const auto t1 = Clock::now();
  camera->start();
  f.start_s = std::chrono::duration<double>(Clock::now() - t1).count();
  const double cpu0 = cpu_s();
  const auto end = Clock::now() + std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(seconds));
  std::uint64_t first_ns = 0, last_ns = 0;
  // As the daemon's run loop: pull promptly, never block on anything else.
  while (Clock::now() < end) {
    if (auto pair = camera->next_pair(std::chrono::milliseconds(50))) {
      if (f.delivered == 0) first_ns = pair->a.host_timestamp_ns;
      last_ns = pair->a.host_timestamp_ns;
      ++f.delivered;
      // Let go as the daemon does: its buffers go back to the camera's frame pool.
      (void)drivers::share_pair(std::move(*pair), camera->frame_pool());
    }
  }
  camera->stop();
  if (f.delivered > 0) f.cpu_ms_per_pair = (cpu_s() - cpu0) * 1e3 / double(f.delivered);
  done = true;
  sampler.join();
  const drivers::CameraCounters c = camera->counters();
  f.frames_lost = c.frames_lost;
  f.overflowed = c.pairs_overflowed;
  if (f.delivered > 1) f.sustained_hz = double(f.delivered - 1) / (double(last_ns - first_ns) * 1e-9);
  return f;
}

}  // namespace

int main(int argc, char** argv) {
  const int recorded = argc > 1 ? std::atoi(argv[1]) : 24;
  const double seconds = argc > 2 ? std::atof(argv[2]) : 30;
  const double rate_hz = argc > 3 ? std::atof(argv[3]) : 10;
  const fs::path camera_file = fs::path(PLENOPIV_SOURCE_DIR) / "systemd/config/camera-fahringer2015.yaml";
  const optics::CameraModel camera = optics::load_camera_file(camera_file);
  const int width = camera.sensor().width_px, height = camera.sensor().height_px;
  const fs::path root = fs::temp_directory_path() / "plenopiv-bench-replay";
  const std::string folder = "paper-" + std::to_string(recorded);
  write_recording(root / folder, recorded, width, height);
  const drivers::ReplaySource source{root, camera_file};
  const double pair_mb = 2.0 * width * height * 2 / (1 << 20);
  // Preloaded: the whole recording decoded at start. Read ahead: a buffer of 4 pairs.
  const std::vector<std::pair<const char*, int>> variants{{"preloaded", int(pair_mb * (recorded + 1))},
                                                          {"read_ahead", int(pair_mb * 4) + 1}};
  for (const auto& [name, buffer_mb] : variants) {
    const std::string uri =
        "replay://" + folder + "?loop=1&rate_hz=" + std::to_string(rate_hz) + "&buffer_mb=" + std::to_string(buffer_mb);
    const Figures f = run(uri, source, seconds);
    std::printf(
        "bench=replay variant=%s frame=%dx%d recorded_pairs=%d buffer_mb=%d rate_hz=%.1f "
        "seconds=%.0f "
        "open_s=%.2f start_s=%.2f delivered=%llu sustained_hz=%.3f cpu_ms_per_pair=%.1f frames_lost=%llu "
        "pairs_overflowed=%llu "
        "rss_min_gb=%.2f rss_max_gb=%.2f\n",
        name, width, height, recorded, buffer_mb, rate_hz, seconds, f.open_s, f.start_s,
        static_cast<unsigned long long>(f.delivered), f.sustained_hz, f.cpu_ms_per_pair,
        static_cast<unsigned long long>(f.frames_lost), static_cast<unsigned long long>(f.overflowed), f.rss_min_gb,
        f.rss_max_gb);
    std::fflush(stdout);
  }
  std::printf("bench=replay peak_rss_gb=%.2f\n", bench::peak_rss_gb());
  return 0;
}
