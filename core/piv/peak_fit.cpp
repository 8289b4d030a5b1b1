// Correlation peaks: the three highest local maxima and their sub-voxel positions.
#include "core/piv/peak_fit.hpp"

#include <algorithm>
#include <cmath>
#include <cstddef>

#include <xmmintrin.h>

namespace plenopiv::piv {
namespace {

int wrap(int i, int n) { return i < 0 ? i + n : (i >= n ? i - n : i); }
int signed_shift(int i, int n) { return i < (n + 1) / 2 ? i : i - n; }

std::size_t index_of(const std::array<int, 3>& s, int x, int y, int z) {
  return (std::size_t(z) * s[1] + y) * s[0] + x;
}

}  // namespace

Peak fit_peak(std::span<const float> corr, const std::array<int, 3>& shape, const std::array<int, 3>& at) {
  Peak p;
  p.value = corr[index_of(shape, at[0], at[1], at[2])];
  for (int axis = 0; axis < 3; ++axis) {
    const int n = shape[axis];
    const int s = signed_shift(at[axis], n);
    if (n < 3) {
      p.shift[axis] = float(s);
      continue;
    }
    std::array<int, 3> lo = at, hi = at;
    lo[axis] = wrap(at[axis] - 1, n);
    hi[axis] = wrap(at[axis] + 1, n);
    const double c0 = p.value;
    const double cm = corr[index_of(shape, lo[0], lo[1], lo[2])];
    const double cp = corr[index_of(shape, hi[0], hi[1], hi[2])];
    double offset = 0;
    if (s == -(n / 2) || s == (n + 1) / 2 - 1) {
      // The neighbour across the border is the same cyclic value seen from the other side: the
      // shift is ambiguous there, so take the centroid of the (clipped) values and say so.
      const double wm = std::max(cm, 0.0), w0 = std::max(c0, 0.0), wp = std::max(cp, 0.0);
      const double sum = wm + w0 + wp;
      offset = sum > 0 ? (wp - wm) / sum : 0.0;
      p.flags |= flag_centroid;
    } else if (cm > 0 && c0 > 0 && cp > 0) {
      const double lm = std::log(cm), l0 = std::log(c0), lp = std::log(cp);
      const double den = 2 * (lm - 2 * l0 + lp);
      offset = den < 0 ? (lm - lp) / den : 0.0;
    } else {
      const double den = 2 * (cm - 2 * c0 + cp);
      offset = den < 0 ? (cm - cp) / den : 0.0;
      p.flags |= flag_parabolic;
    }
    // At a true maximum both fits lie within half a voxel; a flat top must not throw it further.
    offset = std::clamp(offset, -0.5, 0.5);
    p.shift[axis] = float(s + offset);
  }
  return p;
}

std::array<Peak, 3> find_peaks(std::span<const float> corr, const std::array<int, 3>& shape) {
  struct Candidate {
    float value;
    int x, y, z;
  };
  std::array<Candidate, 3> best{};
  int found = 0;
  const int nx = shape[0], ny = shape[1], nz = shape[2];
  // Neighbour offsets; away from the borders no index needs wrapping, and an offset < 0 is a
  // neighbour the scan has already passed.
  std::array<std::ptrdiff_t, 26> offset;
  std::array<std::array<int, 3>, 26> step;
  // The 6 face neighbours come first: most voxels are rejected by one of them, and x +- 1 is
  // in the same cache line.
  int o = 0;
  for (int pass = 0; pass < 2; ++pass)
    for (int dz = -1; dz <= 1; ++dz)
      for (int dy = -1; dy <= 1; ++dy)
        for (int dx = -1; dx <= 1; ++dx) {
          const int nonzero = (dx != 0) + (dy != 0) + (dz != 0);
          if (nonzero == 0 || (nonzero == 1) != (pass == 0)) continue;
          offset[o] = (std::ptrdiff_t(dz) * ny + dy) * nx + dx;
          step[o++] = {dx, dy, dz};
        }
  // Strict against earlier neighbours, non-strict against later ones: a plateau yields exactly
  // one maximum, its first voxel.
  auto beaten = [](float w, float v, bool earlier) { return earlier ? w >= v : w > v; };
  float threshold = 0;
  // One voxel: is it a local maximum above the threshold, and among the three highest so far?
  auto visit = [&](const float* row, int x, int y, int z, bool yz_inside) {
    const float v = row[x];
    // Only values above the third peak so far (or above 0 while fewer than three were found;
    // peaks <= 0 are of no use) need a test.
    if (!(v > threshold)) return;
    if (yz_inside && x > 0 && x < nx - 1) {
      for (int k = 0; k < 26; ++k)
        if (beaten(row[x + offset[k]], v, offset[k] < 0)) return;
    } else {
      for (int k = 0; k < 26; ++k) {
        const float w =
            corr[index_of(shape, wrap(x + step[k][0], nx), wrap(y + step[k][1], ny), wrap(z + step[k][2], nz))];
        if (beaten(w, v, offset[k] < 0)) return;
      }
    }
    int pos = std::min(found, 2);
    while (pos > 0 && best[pos - 1].value < v) {
      best[pos] = best[pos - 1];
      --pos;
    }
    best[pos] = {v, x, y, z};
    found = std::min(found + 1, 3);
    if (found == 3) threshold = best[2].value;
  };
  for (int z = 0; z < nz; ++z) {
    const bool z_inside = z > 0 && z < nz - 1;
    for (int y = 0; y < ny; ++y) {
      const bool yz_inside = z_inside && y > 0 && y < ny - 1;
      const float* row = corr.data() + index_of(shape, 0, y, z);
      // Four voxels per SSE comparison against the threshold: most groups hold none above it
      // and are passed over with one well-predicted branch. The voxels above it are visited in
      // scan order, each tested again (the threshold may have risen), so the result is that of
      // a voxel-by-voxel scan.
      int x = 0;
      for (; x + 4 <= nx; x += 4) {
        int above = _mm_movemask_ps(_mm_cmpgt_ps(_mm_loadu_ps(row + x), _mm_set1_ps(threshold)));
        while (above) {
          visit(row, x + __builtin_ctz(above), y, z, yz_inside);
          above &= above - 1;
        }
      }
      for (; x < nx; ++x) visit(row, x, y, z, yz_inside);
    }
  }
  std::array<Peak, 3> peaks{};
  for (int i = 0; i < found; ++i) peaks[i] = fit_peak(corr, shape, {best[i].x, best[i].y, best[i].z});
  return peaks;
}

float peak_ratio(const std::array<Peak, 3>& peaks) {
  if (peaks[1].value <= 0 || peaks[0].value >= peak_ratio_cap * peaks[1].value) return peak_ratio_cap;
  return peaks[0].value / peaks[1].value;
}

}  // namespace plenopiv::piv
