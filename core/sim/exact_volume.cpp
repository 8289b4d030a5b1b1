// The paper's baseline "exact-particle volume": every particle a 3x3x3 blob at its true position.
#include "core/sim/exact_volume.hpp"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <cmath>
#include <cstdint>

namespace plenopiv::sim {
namespace {

// A particle reduced to what a slice needs: nearest voxel and per-axis taps.
struct Blob {
  int ix, iy, iz;
  float wx[3], wy[3], wz[3];
};

void taps(double d, float w[3]) {
  w[0] = float(0.5 * (0.5 - d) * (0.5 - d));
  w[1] = float(0.75 - d * d);
  w[2] = float(0.5 * (0.5 + d) * (0.5 + d));
}

}  // namespace

Volume render_exact_volume(const Grid3& grid, std::span<const Point3> particles_mm, float peak) {
  Volume volume(grid, 0.f);
  const int nx = grid.shape[0], ny = grid.shape[1], nz = grid.shape[2];
  if (grid.count() == 0) return volume;
  const float scale = peak / 0.421875f;  // 0.75^3: the centre voxel of a centred blob

  // Blobs whose 3x3x3 reach the grid, binned by nearest slice iz in [-1, nz] (counting sort,
  // stable: input order kept inside a bin), so each slice finds its contributors in order.
  std::vector<Blob> blobs;
  blobs.reserve(particles_mm.size());
  std::vector<std::size_t> bin_start(std::size_t(nz) + 3, 0);
  for (const Point3& p : particles_mm) {
    double f[3];
    int n[3];
    bool inside = true;
    for (int a = 0; a < 3; ++a) {
      f[a] = (p[a] - grid.origin_mm[a]) / grid.spacing_mm[a];
      if (!(f[a] > -1.5 && f[a] < grid.shape[a] + 0.5)) inside = false;  // also rejects NaN
    }
    if (!inside) continue;
    for (int a = 0; a < 3; ++a) n[a] = int(std::floor(f[a] + 0.5));
    Blob b{n[0], n[1], n[2], {}, {}, {}};
    taps(f[0] - n[0], b.wx);
    taps(f[1] - n[1], b.wy);
    taps(f[2] - n[2], b.wz);
    blobs.push_back(b);
    ++bin_start[std::size_t(b.iz + 1) + 1];
  }
  for (std::size_t i = 1; i < bin_start.size(); ++i) bin_start[i] += bin_start[i - 1];
  std::vector<Blob> sorted(blobs.size());
  {
    std::vector<std::size_t> fill(bin_start.begin(), bin_start.end() - 1);
    for (const Blob& b : blobs) sorted[fill[std::size_t(b.iz + 1)]++] = b;
  }

  tbb::parallel_for(tbb::blocked_range<int>(0, nz), [&](const tbb::blocked_range<int>& range) {
    for (int z = range.begin(); z != range.end(); ++z) {
      float* slice = volume.data.data() + std::size_t(z) * nx * ny;
      // Contributors have nearest slice z-1, z, z+1: bins (z-1)+1 .. (z+1)+1.
      for (std::size_t k = bin_start[std::size_t(z)]; k < bin_start[std::size_t(z) + 3]; ++k) {
        const Blob& b = sorted[k];
        const float wz = scale * b.wz[z - b.iz + 1];
        for (int dy = -1; dy <= 1; ++dy) {
          const int y = b.iy + dy;
          if (y < 0 || y >= ny) continue;
          const float wzy = wz * b.wy[dy + 1];
          float* row = slice + std::size_t(y) * nx;
          for (int dx = -1; dx <= 1; ++dx) {
            const int x = b.ix + dx;
            if (x < 0 || x >= nx) continue;
            row[x] += wzy * b.wx[dx + 1];
          }
        }
      }
    }
  });
  return volume;
}

}  // namespace plenopiv::sim
