// Window deformation: predictor to every voxel, symmetric 7x7x7 windowed-sinc resampling.
#include "core/piv/deform.hpp"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <numbers>
#include <tuple>

namespace plenopiv::piv {
namespace {

constexpr int table_steps = 256;  // rows per voxel of fractional offset
// The window reaches zero at the outermost tap when the sample lies halfway between voxels, so
// the two stencils meeting there agree and the interpolant is continuous.
constexpr double hann_half_width = 3.5;

double sinc(double t) {
  if (std::abs(t) < 1e-12) return 1.0;
  const double a = std::numbers::pi * t;
  return std::sin(a) / a;
}

// Rows for f = -0.5 + r / table_steps, r = 0 .. table_steps.
struct SincTable {
  std::array<std::array<float, sinc_taps>, table_steps + 1> rows;
  SincTable() {
    for (int r = 0; r <= table_steps; ++r) {
      const double f = -0.5 + double(r) / table_steps;
      double sum = 0;
      std::array<double, sinc_taps> w;
      for (int k = 0; k < sinc_taps; ++k) {
        const double t = f - (k - sinc_taps / 2);
        w[k] = std::abs(t) < hann_half_width
                   ? sinc(t) * (0.5 + 0.5 * std::cos(std::numbers::pi * t / hann_half_width))
                   : 0.0;
        sum += w[k];
      }
      for (int k = 0; k < sinc_taps; ++k) rows[r][k] = float(w[k] / sum);
    }
  }
};

const SincTable& sinc_table() {
  static const SincTable table;
  return table;
}

// Nearest voxel and weights of a coordinate.
struct Taps {
  int base;  // first tap: round(p) - 3
  std::array<float, sinc_taps> w;
};

Taps taps_for(double p) {
  Taps t;
  const double n0 = std::floor(p + 0.5);
  t.base = int(n0) - sinc_taps / 2;
  sinc7_weights(p - n0, t.w);
  return t;
}

// Sum over the 7x7x7 stencil. Inside the volume, each of the 49 rows is read as 8 contiguous
// voxels (the 8th with weight 0) into 8 accumulators, so the compiler can use one vector
// multiply-add per row; the x weights are applied once at the end. The AVX2 clone is chosen at
// run time where the CPU has it.
__attribute__((target_clones("avx2", "default")))
float sample(const float* v, const std::array<int, 3>& s, const Taps& tx, const Taps& ty,
             const Taps& tz) {
  const std::size_t plane = std::size_t(s[0]) * s[1];
  const bool inside = tx.base >= 0 && tx.base + sinc_taps + 1 <= s[0] && ty.base >= 0 &&
                      ty.base + sinc_taps <= s[1] && tz.base >= 0 && tz.base + sinc_taps <= s[2];
  if (inside) {
    float acc[8] = {0, 0, 0, 0, 0, 0, 0, 0};
    for (int kz = 0; kz < sinc_taps; ++kz) {
      const float* slab = v + (tz.base + kz) * plane + std::size_t(ty.base) * s[0] + tx.base;
      for (int ky = 0; ky < sinc_taps; ++ky) {
        const float w = tz.w[kz] * ty.w[ky];
        const float* row = slab + std::size_t(ky) * s[0];
        for (int k = 0; k < 8; ++k) acc[k] += w * row[k];
      }
    }
    float total = 0;
    for (int k = 0; k < sinc_taps; ++k) total += tx.w[k] * acc[k];
    return total;
  }
  float total = 0;
  for (int kz = 0; kz < sinc_taps; ++kz) {
    const int z = tz.base + kz;
    if (z < 0 || z >= s[2]) continue;
    float zsum = 0;
    for (int ky = 0; ky < sinc_taps; ++ky) {
      const int y = ty.base + ky;
      if (y < 0 || y >= s[1]) continue;
      const float* row = v + z * plane + std::size_t(y) * s[0];
      float ysum = 0;
      for (int kx = 0; kx < sinc_taps; ++kx) {
        const int x = tx.base + kx;
        if (x >= 0 && x < s[0]) ysum += tx.w[kx] * row[x];
      }
      zsum += ty.w[ky] * ysum;
    }
    total += tz.w[kz] * zsum;
  }
  return total;
}

}  // namespace

NodeField::NodeField(std::array<int, 3> n, std::array<double, 3> first_node,
                     std::array<double, 3> node_step)
    : count(n), first(first_node), step(node_step) {
  for (auto& c : d) c.assign(size(), 0.f);
}

std::pair<int, double> NodeField::locate(int axis, double p) const {
  const double u = std::clamp((p - first[axis]) / step[axis], 0.0, double(count[axis] - 1));
  const int i0 = std::min(int(u), std::max(count[axis] - 2, 0));
  return {i0, count[axis] > 1 ? u - i0 : 0.0};
}

std::array<float, 3> NodeField::at(double x, double y, double z) const {
  const std::array<double, 3> p{x, y, z};
  std::array<int, 3> i0;
  std::array<double, 3> frac;
  for (int a = 0; a < 3; ++a) std::tie(i0[a], frac[a]) = locate(a, p[a]);
  std::array<float, 3> out{0, 0, 0};
  for (int c = 0; c < 8; ++c) {
    const int dx = c & 1, dy = (c >> 1) & 1, dz = (c >> 2) & 1;
    const double w = (dx ? frac[0] : 1 - frac[0]) * (dy ? frac[1] : 1 - frac[1]) *
                     (dz ? frac[2] : 1 - frac[2]);
    if (w == 0) continue;
    const std::size_t k = index(std::min(i0[0] + dx, count[0] - 1),
                                std::min(i0[1] + dy, count[1] - 1),
                                std::min(i0[2] + dz, count[2] - 1));
    for (int a = 0; a < 3; ++a) out[a] += float(w * d[a][k]);
  }
  return out;
}

std::vector<double> NodeField::mean_weights(int axis, int first_voxel, int n) const {
  std::vector<double> w(count[axis], 0.0);
  for (int v = first_voxel; v < first_voxel + n; ++v) {
    const auto [i0, frac] = locate(axis, v);
    w[i0] += (1 - frac) / n;
    if (frac > 0) w[i0 + 1] += frac / n;
  }
  return w;
}

void sinc7_weights(double f, std::array<float, sinc_taps>& w) {
  const auto& rows = sinc_table().rows;
  const double u = std::clamp((f + 0.5) * table_steps, 0.0, double(table_steps));
  const int r = std::min(int(u), table_steps - 1);
  const float t = float(u - r);
  for (int k = 0; k < sinc_taps; ++k) w[k] = rows[r][k] + t * (rows[r + 1][k] - rows[r][k]);
}

float sample_sinc7(std::span<const float> volume, const std::array<int, 3>& shape, double x,
                   double y, double z) {
  return sample(volume.data(), shape, taps_for(x), taps_for(y), taps_for(z));
}

void binomial_smooth(std::span<const float> in, const std::array<int, 3>& shape,
                     std::span<float> out, std::span<float> scratch) {
  const std::array<std::size_t, 3> stride{1, std::size_t(shape[0]),
                                          std::size_t(shape[0]) * shape[1]};
  // x: in -> out, y: out -> scratch, z: scratch -> out.
  const std::array<const float*, 3> src{in.data(), out.data(), scratch.data()};
  const std::array<float*, 3> dst{out.data(), scratch.data(), out.data()};
  for (int axis = 0; axis < 3; ++axis) {
    const float* s = src[axis];
    float* d = dst[axis];
    const std::size_t st = stride[axis];
    const int n = shape[axis];
    tbb::parallel_for(tbb::blocked_range<int>(0, shape[2]), [&](const tbb::blocked_range<int>& r) {
      for (int z = r.begin(); z < r.end(); ++z)
        for (int y = 0; y < shape[1]; ++y) {
          const std::size_t row = z * stride[2] + y * stride[1];
          for (int x = 0; x < shape[0]; ++x) {
            const std::size_t i = row + x;
            const int c = axis == 0 ? x : axis == 1 ? y : z;
            float v = 0.5f * s[i];
            float w = 0.5f;
            if (c > 0) v += 0.25f * s[i - st], w += 0.25f;
            if (c < n - 1) v += 0.25f * s[i + st], w += 0.25f;
            d[i] = v / w;
          }
        }
    });
  }
}

void deform_pair(std::span<const float> a, std::span<const float> b,
                 const std::array<int, 3>& shape, const NodeField& predictor,
                 std::span<float> a_out, std::span<float> b_out) {
  const std::size_t plane = std::size_t(shape[0]) * shape[1];
  tbb::parallel_for(tbb::blocked_range<int>(0, shape[2]), [&](const tbb::blocked_range<int>& r) {
    for (int z = r.begin(); z < r.end(); ++z) {
      for (int y = 0; y < shape[1]; ++y) {
        for (int x = 0; x < shape[0]; ++x) {
          const auto d = predictor.at(x, y, z);
          const std::size_t i = z * plane + std::size_t(y) * shape[0] + x;
          const double hx = 0.5 * d[0], hy = 0.5 * d[1], hz = 0.5 * d[2];
          a_out[i] = sample(a.data(), shape, taps_for(x - hx), taps_for(y - hy), taps_for(z - hz));
          b_out[i] = sample(b.data(), shape, taps_for(x + hx), taps_for(y + hy), taps_for(z + hz));
        }
      }
    }
  });
}

}  // namespace plenopiv::piv
