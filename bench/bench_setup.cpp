// Setup once per geometry: what a pair operator costs to build, against reading its weight tables
// back from the disk cache and taking it from the in-process cache, side by side in one process.
//
//   bench_setup [paper|small] [--rotation RAD] [--repeat N]
//     paper: camera-fahringer2015.yaml, 300 x 200 x 200 voxels of 0.125 mm plus 1 mm depth guard
//            (run-paper.yaml's box, on cubes); small: camera-small.yaml, 32 x 32 x 32 (process.yaml's box, on cubes).
//     --rotation: the lens array rotated by RAD (0.001745 = 0.1 deg), so the frames are resampled
//            onto an axis-aligned lattice first (default 0: the nominal lattice, raw pixels).
//     --repeat: medians over N builds and N reads (default 3).
// Prints bench=setup lines: seconds (wall) and CPU seconds per phase, the cache file's bytes.
#include <sys/resource.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <string>
#include <vector>

#include "bench/bench_support.hpp"
#include "core/calib/nominal_calibration.hpp"
#include "core/optics/camera_file.hpp"
#include "core/process/operator_cache.hpp"
#include "core/process/process.hpp"

using namespace plenopiv;

namespace {

using bench::now_s;
double cpu_s() {
  rusage u{};
  getrusage(RUSAGE_SELF, &u);
  return double(u.ru_utime.tv_sec + u.ru_stime.tv_sec) + 1e-6 * double(u.ru_utime.tv_usec + u.ru_stime.tv_usec);
}

struct Timing {
  std::vector<double> wall, cpu;
  void add(double w, double c) {
    wall.push_back(w);
    cpu.push_back(c);
  }
};

}  // namespace

int main(int argc, char** argv) {
  std::setvbuf(stdout, nullptr, _IOLBF, 0);
  std::string scale = "paper";
  double rotation = 0;
  int repeat = 3;
  for (int i = 1; i < argc; ++i) {
    if (!std::strcmp(argv[i], "--rotation") && i + 1 < argc)
      rotation = std::stod(argv[++i]);
    else if (!std::strcmp(argv[i], "--repeat") && i + 1 < argc)
      repeat = std::max(1, std::stoi(argv[++i]));
    else
      scale = argv[i];
  }
  const bool paper = scale == "paper";
  if (!paper && scale != "small") {
    std::fprintf(stderr, "usage: bench_setup [paper|small] [--rotation RAD] [--repeat N]\n");
    return 2;
  }
  const std::string dir = std::string(PLENOPIV_SOURCE_DIR) + "/systemd/config/";
  const auto camera = optics::load_camera_file(dir + (paper ? "camera-fahringer2015.yaml" : "camera-small.yaml"));
  optics::Lattice lattice = optics::Lattice::nominal(camera);
  lattice.rotation_rad = rotation;
  const optics::MicrolensArray lenses = optics::MicrolensArray::from_lattice(lattice);
  double t = now_s(), c = cpu_s();
  const ImageF white = calib::geometric_white_image(camera, lenses);
  std::printf("bench=setup case=%s rotation_rad=%g phase=white_image seconds=%.3f cpu_s=%.3f\n", scale.c_str(),
              rotation, now_s() - t, cpu_s() - c);
  process::ProcessSettings settings;
  const double voxel = 0.125, hx = paper ? 18.75 : 2, hy = paper ? 12.5 : 2, hz = paper ? 12.5 : 2;
  settings.grid = process::grid_for_extent({-hx, -hy, -hz}, {hx, hy, hz}, {voxel, voxel, voxel}, "bench");
  const std::filesystem::path folder = std::filesystem::temp_directory_path() / "plenopiv-bench-setup";
  std::filesystem::remove_all(folder);

  Timing build, first_write, read, memory;
  std::uintmax_t file_bytes = 0;
  std::size_t table_bytes = 0;
  std::uint64_t hash_built = 0, hash_read = 0;
  for (int k = 0; k < repeat; ++k) {
    t = now_s(), c = cpu_s();
    const process::PairOperator built(camera, lenses, white, settings);
    build.add(now_s() - t, cpu_s() - c);
    table_bytes = built.weights().bytes();
    hash_built = bench::bits_hash(built.weights().normalisers());
    std::filesystem::remove_all(folder);
    process::WeightsDiskCache cache(folder);
    t = now_s(), c = cpu_s();
    const process::PairOperator written(camera, lenses, white, settings, cache.source());
    first_write.add(now_s() - t, cpu_s() - c);
    for (const auto& e : std::filesystem::directory_iterator(folder)) file_bytes = e.file_size();
    t = now_s(), c = cpu_s();
    const process::PairOperator from_disk(camera, lenses, white, settings, cache.source());
    read.add(now_s() - t, cpu_s() - c);
    if (cache.last_outcome() != process::WeightsDiskCache::Outcome::hit) {
      std::fprintf(stderr, "bench_setup: the cache missed: %s\n", cache.last_note().c_str());
      return 1;
    }
    hash_read = bench::bits_hash(from_disk.weights().normalisers());
  }
  process::OperatorCache kept(2);
  kept.get(camera, lenses, white, settings);
  for (int k = 0; k < repeat; ++k) {
    t = now_s(), c = cpu_s();
    kept.get(camera, lenses, white, settings);
    memory.add(now_s() - t, cpu_s() - c);
  }
  const double b = bench::median(build.wall);
  for (const auto& [name, timing] : {std::pair<const char*, const Timing*>{"build", &build},
                                     {"build_and_write_cache", &first_write},
                                     {"read_cache", &read},
                                     {"in_process_cache", &memory}}) {
    std::printf(
        "bench=setup case=%s rotation_rad=%g phase=%s seconds=%.3f cpu_s=%.3f "
        "ratio_to_build=%.3f\n",
        scale.c_str(), rotation, name, bench::median(timing->wall), bench::median(timing->cpu),
        bench::median(timing->wall) / b);
  }
  std::printf(
      "bench=setup case=%s rotation_rad=%g voxels=%zu table_mb=%.1f file_mb=%.1f same_tables=%d "
      "peak_rss_gb=%.2f\n",
      scale.c_str(), rotation, settings.reconstruction_grid().count(), double(table_bytes) / (1 << 20),
      double(file_bytes) / (1 << 20), int(hash_built == hash_read), bench::peak_rss_gb());
  std::filesystem::remove_all(folder);
  return 0;
}
