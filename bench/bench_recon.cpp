// Reconstruction benchmarks: paper-scale SMART (phases, memory, skipping) and the matrix-free
// operator against the explicit matrix on a mid-size case, side by side in one process.
#include <sys/resource.h>
#include <tbb/global_control.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <random>
#include <string>

#include "core/optics/camera_file.hpp"
#include "core/recon/mart.hpp"
#include "core/recon/quality.hpp"
#include "core/recon/weights.hpp"

using namespace plenopiv;
using Clock = std::chrono::steady_clock;

namespace {

double since(Clock::time_point t) { return std::chrono::duration<double>(Clock::now() - t).count(); }

// Process CPU time (all threads): on a shared machine wall time says more about the neighbours.
double cpu_seconds() {
  rusage u{};
  getrusage(RUSAGE_SELF, &u);
  return double(u.ru_utime.tv_sec + u.ru_stime.tv_sec) + 1e-6 * double(u.ru_utime.tv_usec + u.ru_stime.tv_usec);
}

double peak_rss_gb() {
  std::ifstream in("/proc/self/status");
  std::string line;
  while (std::getline(in, line)) {
    if (line.rfind("VmHWM:", 0) == 0) return std::stod(line.substr(6)) / (1024.0 * 1024.0);
  }
  return -1;
}

// Particles as trilinear deposits of unit light at random positions (seeded), and the image the
// operator makes of them: a stand-in until the ray-traced simulator (core/sim) lands.
Volume particle_volume(const Grid3& g, int count, unsigned seed) {
  Volume v(g, 0.f);
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  for (int p = 0; p < count; ++p) {
    const double fx = 1 + u(rng) * (g.shape[0] - 3), fy = 1 + u(rng) * (g.shape[1] - 3), fz = 1 + u(rng) * (g.shape[2] - 3);
    const int x = int(fx), y = int(fy), z = int(fz);
    const double tx = fx - x, ty = fy - y, tz = fz - z;
    for (int c = 0; c < 8; ++c) {
      const double w = (c & 1 ? tx : 1 - tx) * (c & 2 ? ty : 1 - ty) * (c & 4 ? tz : 1 - tz);
      v.at(x + (c & 1), y + (c >> 1 & 1), z + (c >> 2 & 1)) += float(w);
    }
  }
  return v;
}

Grid3 grid_of(int nx, int ny, int nz, double voxel_mm, double depth_mm) {
  Grid3 g;
  g.shape = {nx, ny, nz};
  g.spacing_mm = {voxel_mm, voxel_mm, depth_mm / nz};
  g.origin_mm = {-0.5 * (nx - 1) * voxel_mm, -0.5 * (ny - 1) * voxel_mm, -0.5 * (nz - 1) * depth_mm / nz};
  return g;
}

void paper_scale(const std::string& source_dir, double ppm, int iterations, float threshold_fraction,
                 double dark_cutoff) {
  const auto cam = optics::load_camera_file(source_dir + "/systemd/config/camera-fahringer2015.yaml");
  const auto lenses = optics::MicrolensArray::from_lattice(optics::Lattice::nominal(cam));
  // The paper's 500-particle box: 30 x 20 x 20 mm in 300 x 200 x 200 voxels of 0.1 mm.
  const Grid3 g = grid_of(300, 200, 200, 0.1, 20.0);
  auto t = Clock::now();
  double c = cpu_seconds();
  ImageF white = recon::geometric_white_image(cam, lenses);
  std::printf("bench=recon_paper phase=white_image seconds=%.3f cpu_s=%.3f\n", since(t), cpu_seconds() - c);
  t = Clock::now();
  c = cpu_seconds();
  const recon::WeightingOperator op(cam, lenses, g, std::move(white));
  std::printf("bench=recon_paper phase=tables_and_normalisers seconds=%.3f cpu_s=%.3f\n", since(t), cpu_seconds() - c);

  const int particles = int(std::lround(ppm * lenses.lattice.count()));
  const Volume truth = particle_volume(g, particles, 1);
  ImageF image(op.image_width(), op.image_height(), 0.f);
  t = Clock::now();
  op.project(truth.data, image.pixels);
  std::printf("bench=recon_paper phase=dense_projection_of_truth seconds=%.3f\n", since(t));
  float peak = 0;
  for (float v : image.pixels) peak = std::max(peak, v);
  for (float& v : image.pixels) v = std::round(v / peak * 4000.f);  // 12-bit-like counts
  std::size_t lit = 0;
  for (float v : image.pixels) lit += v > 0;

  recon::MartSettings s;
  s.iterations = iterations;
  s.mu = 0.5;
  s.noise_threshold = threshold_fraction * 4000.f;
  s.dark_weight_cutoff = dark_cutoff;
  t = Clock::now();
  c = cpu_seconds();
  const recon::MartResult r = recon::reconstruct(op, image, s, [](const recon::IterationReport& it) {
    std::printf("bench=recon_paper phase=iteration n=%d seconds=%.3f residual=%.4f\n", it.iteration, it.seconds,
                it.residual);
  });
  const double t_mart = since(t), c_mart = cpu_seconds() - c;
  double iter_total = 0;
  for (const auto& it : r.iterations) iter_total += it.seconds;
  const recon::SkipReport& k = r.skipped;
  std::printf("bench=recon_paper particles=%d ppm=%.2f lit_pixel_fraction=%.4f threshold_counts=%.1f dark_cutoff=%.2f\n",
              particles, ppm, double(lit) / double(image.size()), double(s.noise_threshold), dark_cutoff);
  std::printf("bench=recon_paper phase=active_set_and_mlos seconds=%.3f\n", r.setup_seconds);
  std::printf("bench=recon_paper phase=iterations seconds=%.3f per_iteration=%.3f\n", iter_total,
              iter_total / std::max<std::size_t>(1, r.iterations.size()));
  std::printf("bench=recon_paper phase=reconstruct_total seconds=%.3f cpu_s=%.3f final_residual=%.4f\n", t_mart, c_mart,
              r.final_residual);
  std::printf("bench=recon_paper voxels=%zu active=%zu skipped_fraction=%.4f dark=%zu unseen=%zu slices_empty=%d "
              "dark_pixels=%zu\n",
              k.voxels, k.voxels_active, k.fraction_skipped(), k.voxels_dark, k.voxels_unseen, k.slices_empty,
              k.dark_pixels);
  std::printf("bench=recon_paper quality_q_star=%.4f (truth = the trilinear particle deposits; own forward model)\n",
              recon::quality_factor(r.volume, truth));
  std::printf("bench=recon_paper peak_rss_gb=%.3f\n", peak_rss_gb());
}

void mid_size(const std::string& source_dir) {
  const auto cam = optics::load_camera_file(source_dir + "/systemd/config/camera-small.yaml");
  const auto lenses = optics::MicrolensArray::from_lattice(optics::Lattice::nominal(cam));
  const Grid3 g = grid_of(32, 32, 32, 0.125, 10.0);
  const recon::WeightingOperator op(cam, lenses, g, recon::geometric_white_image(cam, lenses));
  auto t = Clock::now();
  const recon::SparseMatrix w = recon::build_explicit_matrix(op);
  const double t_build = since(t);
  std::vector<float> x(g.count()), img(op.pixel_count()), back(g.count());
  std::mt19937 rng(3);
  std::uniform_real_distribution<float> u(0.f, 1.f);
  for (float& v : x) v = u(rng);
  auto median = [](auto f) {
    std::vector<double> times;
    for (int k = 0; k < 5; ++k) {
      const auto t0 = Clock::now();
      f();
      times.push_back(since(t0));
    }
    std::sort(times.begin(), times.end());
    return times[2];
  };
  const double ex_p = median([&] { w.multiply(x, img); });
  const double ex_b = median([&] { w.multiply_transpose(img, back); });
  const double mf_p = median([&] { op.project(x, img); });
  const double mf_b = median([&] { op.back_project(img, back); });
  std::printf("bench=recon_mid voxels=%zu nonzeros=%zu explicit_bytes=%zu build_s=%.3f\n", g.count(), w.nonzeros(),
              w.nonzeros() * 8 + w.row_start.size() * 8, t_build);
  std::printf("bench=recon_mid op=project variant=explicit median_s=%.4f\n", ex_p);
  std::printf("bench=recon_mid op=project variant=matrix_free median_s=%.4f ratio=%.2f\n", mf_p, ex_p / mf_p);
  std::printf("bench=recon_mid op=back_project variant=explicit median_s=%.4f\n", ex_b);
  std::printf("bench=recon_mid op=back_project variant=matrix_free median_s=%.4f ratio=%.2f\n", mf_b, ex_b / mf_b);
}

}  // namespace

int main(int argc, char** argv) {
  std::string which = argc > 1 ? argv[1] : "all";
  const std::string source_dir = PLENOPIV_SOURCE_DIR;
  const double ppm = argc > 2 ? std::stod(argv[2]) : 0.5;
  const float threshold = argc > 3 ? std::stof(argv[3]) : 0.001f;
  const double cutoff = argc > 4 ? std::stod(argv[4]) : 0.1;
  if (which == "mid" || which == "all") mid_size(source_dir);
  if (which == "paper" || which == "all") paper_scale(source_dir, ppm, 5, threshold, cutoff);
  return 0;
}
