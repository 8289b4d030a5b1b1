// Live path throughput and latency: ray-traced pairs (camera-small) through the daemon's TBB
// pipeline with the real processing stage (MART + 3D correlation), a preview and a full setting.
#include <tbb/global_control.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <map>
#include <mutex>
#include <thread>

#include "core/optics/camera_file.hpp"
#include "core/sim/particles.hpp"
#include "core/sim/render.hpp"
#include "daemon/pipeline.hpp"
#include "daemon/processing.hpp"

using namespace plenopiv;
using Clock = std::chrono::steady_clock;

namespace {

struct Variant {
  const char* name;
  std::string config;
};

struct Figures {
  double median_latency_s = 0, max_latency_s = 0, pairs_per_s = 0;
  std::uint64_t processed = 0, skipped = 0;
};

// Feeds `pairs` at `rate_hz` (0: as fast as the pipeline takes them, one waiting at a time) and
// times each from hand-over to output.
Figures run(const std::vector<daemon::SharedPair>& pairs, const daemon::ProcessFn& process, double rate_hz,
            int in_flight) {
  daemon::LiveMailbox mailbox;
  daemon::PipelineStats stats;
  const daemon::CancelFlag cancel{false};
  std::mutex mutex;
  std::map<std::uint64_t, Clock::time_point> handed;
  std::vector<double> latency;
  const auto start = Clock::now();
  std::thread feeder([&] {
    for (std::size_t i = 0; i < pairs.size(); ++i) {
      if (rate_hz > 0) {
        std::this_thread::sleep_until(
            start + std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(i / rate_hz)));
      } else {
        while (mailbox.depth() > 0) std::this_thread::sleep_for(std::chrono::milliseconds(1));
      }
      {
        std::lock_guard lock(mutex);
        handed[pairs[i]->pair_index] = Clock::now();
      }
      mailbox.push(pairs[i]);
    }
    mailbox.close();
  });
  daemon::run_live_pipeline(
      mailbox, in_flight, process,
      [&](const drivers::FramePair& pair, daemon::ProcessedPair&) {
        std::lock_guard lock(mutex);
        latency.push_back(std::chrono::duration<double>(Clock::now() - handed[pair.pair_index]).count());
      },
      stats, cancel);
  feeder.join();
  const double wall = std::chrono::duration<double>(Clock::now() - start).count();
  Figures f;
  std::sort(latency.begin(), latency.end());
  f.median_latency_s = latency.empty() ? 0 : latency[latency.size() / 2];
  f.max_latency_s = latency.empty() ? 0 : latency.back();
  f.processed = stats.output.processed;
  f.skipped = mailbox.dropped();
  f.pairs_per_s = double(f.processed) / wall;
  return f;
}

}  // namespace

int main(int argc, char** argv) {
  const int count = argc > 1 ? std::atoi(argv[1]) : 6;
  const double rate_hz = argc > 2 ? std::atof(argv[2]) : 1.0;
  const optics::CameraModel camera =
      optics::load_camera_file(std::string(PLENOPIV_SOURCE_DIR) + "/systemd/config/camera-small.yaml");
  const auto lenses = optics::MicrolensArray::from_lattice(optics::Lattice::nominal(camera));
  // Pairs: 60 particles in a 4 x 4 x 2 mm box, displaced 0.25 mm along x between exposures.
  std::vector<daemon::SharedPair> pairs;
  sim::RenderOptions render;
  render.rays_per_particle = 100000;
  for (int i = 0; i < count; ++i) {
    const auto a = sim::random_particles({{-2, -2, -1}, {2, 2, 1}}, 60, 100 + std::uint64_t(i));
    auto b = a;
    for (auto& p : b) p[0] += 0.25;
    auto pair = std::make_shared<drivers::FramePair>();
    pair->pair_index = std::uint64_t(i);
    pair->a.image = sim::render(camera, lenses, a, render, 2 * std::uint64_t(i)).image;
    pair->b.image = sim::render(camera, lenses, b, render, 2 * std::uint64_t(i) + 1).image;
    pairs.push_back(pair);
  }
  const std::string volume = "volume: {x_mm: [-2, 2], y_mm: [-2, 2], z_mm: [-1, 1], ";
  const std::vector<Variant> variants{
      {"preview", volume + "voxel_mm: 0.25}\nreconstruction: {iterations: 3, mu: 1}\n"
                           "correlation: {passes: [{window: 8, overlap_percent: 50}]}\n"},
      {"full", volume + "voxel_mm: 0.125}\nreconstruction: {iterations: 5, mu: 1}\n"
                        "correlation: {passes: [{window: 16, overlap_percent: 50}, "
                        "{window: 8, overlap_percent: 50}]}\n"},
  };
  double reference = 0;
  for (const Variant& v : variants) {
    const daemon::RunConfig config = daemon::parse_run_config("dt_s: 0.001\n" + v.config, v.name);
    const auto t0 = Clock::now();
    const daemon::ProcessFn process =
        daemon::plenoptic_processing(camera)(config, daemon::RunCalibration{}, process::Tier::full, {});
    const double setup = std::chrono::duration<double>(Clock::now() - t0).count();
    const Figures sustained = run(pairs, process, 0.0, 2);
    const Figures paced = run(pairs, process, rate_hz, 2);
    if (reference == 0) reference = sustained.pairs_per_s;
    const auto g = config.volume_grid();
    std::printf(
        "bench=daemon_live variant=%s voxels=%dx%dx%d setup_s=%.2f sustained_pairs_per_s=%.3f "
        "ratio=%.2f paced_rate_hz=%.2f paced_median_latency_s=%.3f paced_max_latency_s=%.3f "
        "paced_processed=%llu paced_skipped=%llu\n",
        v.name, g.shape[0], g.shape[1], g.shape[2], setup, sustained.pairs_per_s, sustained.pairs_per_s / reference,
        rate_hz, paced.median_latency_s, paced.max_latency_s, static_cast<unsigned long long>(paced.processed),
        static_cast<unsigned long long>(paced.skipped));
    std::fflush(stdout);
  }
  return 0;
}
