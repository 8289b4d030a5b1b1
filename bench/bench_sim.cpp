// Ray-tracer throughput: rays/s at 1 and 2 threads with and without diffraction, and the
// paper-size image (4904 x 3280, 289 x 193 lenses, 0.5 ppm, 10 000 rays per particle).
// Usage: bench_sim [--particles N] (N particles for the thread-scaling runs; default 2000)
//                  [--skip-paper]
#include <tbb/global_control.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <ctime>
#include <string>
#include <vector>

#include "core/optics/camera_file.hpp"
#include "core/sim/particles.hpp"
#include "core/sim/render.hpp"

using namespace plenopiv;

namespace {

// The paper's prototype camera (tables 1-2), as shipped.
optics::CameraModel paper_camera() {
  return optics::load_camera_file(std::string(PLENOPIV_SOURCE_DIR) + "/systemd/config/camera-fahringer2015.yaml");
}

double seconds_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

// Median of `repeats` timed renders.
double time_render(const optics::CameraModel& camera, const optics::MicrolensArray& array,
                   const std::vector<sim::Point3>& particles, const sim::RenderOptions& options, int threads,
                   int repeats, sim::RayCounts& counts, double& cpu_s) {
  tbb::global_control limit(tbb::global_control::max_allowed_parallelism, threads);
  std::vector<double> times, cpu;
  for (int r = 0; r < repeats; ++r) {
    const auto t0 = std::chrono::steady_clock::now();
    const std::clock_t c0 = std::clock();
    counts = sim::render(camera, array, particles, options, 1).counts;
    cpu.push_back(double(std::clock() - c0) / CLOCKS_PER_SEC);
    times.push_back(seconds_since(t0));
  }
  std::sort(times.begin(), times.end());
  std::sort(cpu.begin(), cpu.end());
  cpu_s = cpu[cpu.size() / 2];
  return times[times.size() / 2];
}

}  // namespace

int main(int argc, char** argv) {
  std::size_t scaling_particles = 2000;
  bool paper = true;
  for (int i = 1; i < argc; ++i) {
    if (!std::strcmp(argv[i], "--particles") && i + 1 < argc) scaling_particles = std::stoul(argv[++i]);
    if (!std::strcmp(argv[i], "--skip-paper")) paper = false;
  }
  const optics::CameraModel camera = paper_camera();
  const optics::MicrolensArray array = optics::MicrolensArray::from_lattice(optics::Lattice::nominal(camera));
  const sim::Box box = sim::field_of_view_box(camera, -10, 10);
  const auto some = sim::random_particles(box, scaling_particles, 3);

  // The per-image cost that does not depend on rays (zeroing, converting and scaling a 16 Mpixel
  // frame) is timed with no particles and subtracted for the ray rates.
  double overhead[3] = {0, 0, 0};
  for (int threads : {1, 2}) {
    sim::RayCounts counts;
    double cpu = 0;
    overhead[threads] = time_render(camera, array, {}, sim::RenderOptions{}, threads, 3, counts, cpu);
    std::printf("bench=sim_frame_overhead threads=%d median_s=%.3f cpu_s=%.3f\n", threads, overhead[threads], cpu);
  }
  for (double sigma : {0.0, 0.0052}) {
    sim::RenderOptions options;
    options.diffraction_sigma_mm = sigma;
    double t1 = 0;
    for (int threads : {1, 2}) {
      sim::RayCounts counts;
      double cpu = 0;
      const double t = time_render(camera, array, some, options, threads, 3, counts, cpu);
      if (threads == 1) t1 = t;
      // CPU seconds are steadier than wall time on a shared machine: both are printed.
      std::printf(
          "bench=sim_rays variant=%s threads=%d particles=%zu rays=%llu median_s=%.3f "
          "mrays_per_s=%.1f tracing_mrays_per_s=%.1f cpu_s=%.3f mrays_per_cpu_s=%.1f "
          "speedup_vs_1_thread=%.2f\n",
          sigma > 0 ? "diffraction_5.2um" : "no_diffraction", threads, some.size(), (unsigned long long)counts.emitted,
          t, counts.emitted / t * 1e-6, counts.emitted / (t - overhead[threads]) * 1e-6, cpu,
          counts.emitted / cpu * 1e-6, t1 / t);
    }
  }
  if (paper) {
    const std::size_t n = sim::particle_count_from_ppm(camera, box, 0.5);
    const auto particles = sim::random_particles(box, n, 5);
    sim::RenderOptions options;  // 10 000 rays, diffraction 5.2 um: the paper's settings
    sim::RayCounts counts;
    double cpu = 0;
    const double t = time_render(camera, array, particles, options, 2, 1, counts, cpu);
    std::printf(
        "bench=sim_paper_image variant=4904x3280_0.5ppm threads=2 particles=%zu rays=%llu "
        "seconds=%.2f mrays_per_s=%.1f cpu_s=%.2f landed_fraction=%.4f\n",
        n, (unsigned long long)counts.emitted, t, counts.emitted / t * 1e-6, cpu,
        double(counts.landed) / counts.emitted);
  }
  return 0;
}
