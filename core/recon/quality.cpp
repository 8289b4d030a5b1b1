// Reconstruction quality: Q* (eq 14) and the 3D Gaussian particle fit.
#include "core/recon/quality.hpp"

#include <algorithm>
#include <cmath>

#include "core/base/errors.hpp"

namespace plenopiv::recon {

double quality_factor(const Volume& reconstructed, const Volume& exact) {
  if (!(reconstructed.grid == exact.grid) || reconstructed.data.size() != exact.data.size()) {
    throw InputError("Q*: the reconstructed and exact volumes must share one grid");
  }
  const std::size_t n = exact.data.size();
  if (n == 0) return 0.0;
  double ma = 0, mb = 0;
  for (std::size_t i = 0; i < n; ++i) {
    ma += reconstructed.data[i];
    mb += exact.data[i];
  }
  ma /= double(n);
  mb /= double(n);
  double ab = 0, aa = 0, bb = 0;
  for (std::size_t i = 0; i < n; ++i) {
    const double a = reconstructed.data[i] - ma, b = exact.data[i] - mb;
    ab += a * b;
    aa += a * a;
    bb += b * b;
  }
  return aa > 0 && bb > 0 ? ab / std::sqrt(aa * bb) : 0.0;
}

namespace {

struct Brightest {
  std::array<int, 3> voxel{-1, -1, -1};
  float value = 0;
};

// The brightest voxel within half_size of guess_mm (value 0 when the window holds no positive
// intensity or lies outside the grid).
Brightest brightest_near(const Volume& volume, const std::array<double, 3>& guess_mm,
                         const std::array<int, 3>& half_size) {
  const Grid3& g = volume.grid;
  std::array<int, 3> lo{}, hi{};
  for (int a = 0; a < 3; ++a) {
    const int centre = int(std::lround((guess_mm[a] - g.origin_mm[a]) / g.spacing_mm[a]));
    lo[a] = std::max(0, centre - half_size[a]);
    hi[a] = std::min(g.shape[a] - 1, centre + half_size[a]);
    if (lo[a] > hi[a]) return {};
  }
  Brightest b;
  for (int z = lo[2]; z <= hi[2]; ++z) {
    for (int y = lo[1]; y <= hi[1]; ++y) {
      for (int x = lo[0]; x <= hi[0]; ++x) {
        if (volume.at(x, y, z) > b.value) b = {{x, y, z}, volume.at(x, y, z)};
      }
    }
  }
  return b;
}

}  // namespace

std::optional<ParticleFit> fit_particle(const Volume& volume, const std::array<double, 3>& guess_mm,
                                        const std::array<int, 3>& half_size) {
  const Grid3& g = volume.grid;
  const Brightest brightest = brightest_near(volume, guess_mm, half_size);
  const std::array<int, 3>& best = brightest.voxel;
  const float peak = brightest.value;
  if (!(peak > 0)) return std::nullopt;
  ParticleFit fit;
  fit.peak = peak;
  for (int a = 0; a < 3; ++a) {
    // Weighted least squares of ln I = c0 + c1 t + c2 t^2 (t = offset from the peak), weights I^2
    // so that faint tails (noisy logs) count little.
    double s[5] = {0, 0, 0, 0, 0}, r[3] = {0, 0, 0};
    auto add = [&](int t) {
      std::array<int, 3> p = best;
      p[a] += t;
      if (p[a] < 0 || p[a] >= g.shape[a] || std::abs(t) > half_size[a]) return false;
      const float v = volume.at(p[0], p[1], p[2]);
      if (!(v > 0.25f * peak)) return false;
      const double w = double(v) * v / (double(peak) * peak), l = std::log(double(v) / peak);
      double tp = 1;
      for (int k = 0; k < 5; ++k) {
        s[k] += w * tp;
        if (k < 3) r[k] += w * tp * l;
        tp *= t;
      }
      return true;
    };
    add(0);
    int used = 1;
    for (int t = 1; add(t); ++t) ++used;
    for (int t = -1; add(t); --t) ++used;
    double offset = 0;
    if (used >= 3) {
      // Solve the 3x3 normal equations by Cramer's rule.
      const double m[3][3] = {{s[0], s[1], s[2]}, {s[1], s[2], s[3]}, {s[2], s[3], s[4]}};
      auto det3 = [](const double q[3][3]) {
        return q[0][0] * (q[1][1] * q[2][2] - q[1][2] * q[2][1]) - q[0][1] * (q[1][0] * q[2][2] - q[1][2] * q[2][0]) +
               q[0][2] * (q[1][0] * q[2][1] - q[1][1] * q[2][0]);
      };
      const double d = det3(m);
      double m1[3][3], m2[3][3];
      for (int i = 0; i < 3; ++i) {
        for (int j = 0; j < 3; ++j) {
          m1[i][j] = j == 1 ? r[i] : m[i][j];
          m2[i][j] = j == 2 ? r[i] : m[i][j];
        }
      }
      if (std::abs(d) > 1e-300) {
        const double c1 = det3(m1) / d, c2 = det3(m2) / d;
        if (c2 < 0) offset = std::clamp(-c1 / (2 * c2), -1.0, 1.0);
      }
    }
    fit.position_voxel[a] = best[a] + offset;
    fit.position_mm[a] = g.origin_mm[a] + fit.position_voxel[a] * g.spacing_mm[a];
  }
  return fit;
}

std::optional<ParticleFit> fit_particle_moments(const Volume& volume, const std::array<double, 3>& guess_mm,
                                                const std::array<int, 3>& half_size, int lateral_radius) {
  if (lateral_radius < 0) throw InputError("particle fit: lateral radius must be >= 0 voxels");
  const Grid3& g = volume.grid;
  const Brightest brightest = brightest_near(volume, guess_mm, half_size);
  if (!(brightest.value > 0)) return std::nullopt;
  const std::array<int, 3> radius{lateral_radius, lateral_radius, half_size[2]};
  std::array<int, 3> lo{}, hi{};
  for (int a = 0; a < 3; ++a) {
    lo[a] = std::max(0, brightest.voxel[a] - radius[a]);
    hi[a] = std::min(g.shape[a] - 1, brightest.voxel[a] + radius[a]);
  }
  double total = 0;
  std::array<double, 3> moment{0, 0, 0};
  for (int z = lo[2]; z <= hi[2]; ++z) {
    for (int y = lo[1]; y <= hi[1]; ++y) {
      for (int x = lo[0]; x <= hi[0]; ++x) {
        const double v = volume.at(x, y, z);
        total += v;
        moment[0] += v * x;
        moment[1] += v * y;
        moment[2] += v * z;
      }
    }
  }
  ParticleFit fit;
  fit.peak = brightest.value;
  for (int a = 0; a < 3; ++a) {
    fit.position_voxel[a] = moment[a] / total;  // total >= the peak > 0
    fit.position_mm[a] = g.origin_mm[a] + fit.position_voxel[a] * g.spacing_mm[a];
  }
  return fit;
}

}  // namespace plenopiv::recon
