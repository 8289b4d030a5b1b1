// Correlation peaks: the three highest local maxima and their sub-voxel positions.
#include "core/piv/peak_fit.hpp"

#include <algorithm>
#include <cmath>
#include <cstddef>

#include <immintrin.h>
#include <xmmintrin.h>

#include "core/base/isa.hpp"

namespace plenopiv::piv {
namespace {

int wrap(int i, int n) { return i < 0 ? i + n : (i >= n ? i - n : i); }
int signed_shift(int i, int n) { return i < (n + 1) / 2 ? i : i - n; }

std::size_t index_of(const std::array<int, 3>& s, int x, int y, int z) {
  return (std::size_t(z) * s[1] + y) * s[0] + x;
}

// A 16-voxel row's pre-test in one AVX-512 vector (the windows' common width along x): each voxel
// above `threshold` and beaten by none of its 6 face neighbours (the row's cyclic x neighbours by a
// lane rotation; `earlier_y`, `later_y`, `earlier_z`, `later_z` the neighbouring rows), with the
// comparisons of find_peaks' 4-voxel groups. Bit x set: voxel x goes on to the full test.
__attribute__((target("avx512f"))) unsigned row16_candidates_avx512(const float* row, const float* earlier_y,
                                                                    const float* later_y, const float* earlier_z,
                                                                    const float* later_z, float threshold) {
  const __m512 v = _mm512_loadu_ps(row);
  // Lane x takes lane x - 1 (lane 0 lane 15), and lane x + 1 (lane 15 lane 0); the masked form, all
  // lanes set, because GCC 12 warns of the plain one's undefined pass-through.
  const __m512 left =
      _mm512_mask_permutexvar_ps(v, 0xFFFF, _mm512_set_epi32(14, 13, 12, 11, 10, 9, 8, 7, 6, 5, 4, 3, 2, 1, 0, 15), v);
  const __m512 right =
      _mm512_mask_permutexvar_ps(v, 0xFFFF, _mm512_set_epi32(0, 15, 14, 13, 12, 11, 10, 9, 8, 7, 6, 5, 4, 3, 2, 1), v);
  __mmask16 keep = _mm512_cmp_ps_mask(v, _mm512_set1_ps(threshold), _CMP_GT_OQ);
  // Earlier neighbours beat at >=, later ones at > (a NaN neighbour beats nothing).
  keep &= _mm512_cmp_ps_mask(left, v, _CMP_NGE_UQ);
  keep &= _mm512_cmp_ps_mask(right, v, _CMP_NGT_UQ);
  keep &= _mm512_cmp_ps_mask(_mm512_loadu_ps(earlier_y), v, _CMP_NGE_UQ);
  keep &= _mm512_cmp_ps_mask(_mm512_loadu_ps(later_y), v, _CMP_NGT_UQ);
  keep &= _mm512_cmp_ps_mask(_mm512_loadu_ps(earlier_z), v, _CMP_NGE_UQ);
  keep &= _mm512_cmp_ps_mask(_mm512_loadu_ps(later_z), v, _CMP_NGT_UQ);
  return keep;
}

// row16_candidates_avx512's test of lanes 1-14 in two overlapping AVX2 vectors (lanes 1-8 and
// 7-14), the x neighbours loaded one lane before and after, with the same comparisons; lanes 0 and
// 15 (whose x neighbours wrap) are left to the caller. Bit x set: voxel x goes on to the full test.
__attribute__((target("avx2"))) unsigned row16_inner_candidates_avx2(const float* row, const float* earlier_y,
                                                                     const float* later_y, const float* earlier_z,
                                                                     const float* later_z, float threshold) {
  const __m256 bar = _mm256_set1_ps(threshold);
  unsigned keep = 0;
  for (const int x : {1, 7}) {
    const __m256 v = _mm256_loadu_ps(row + x);
    // Earlier neighbours beat at >=, later ones at > (a NaN neighbour beats nothing).
    __m256 k = _mm256_cmp_ps(v, bar, _CMP_GT_OQ);
    k = _mm256_and_ps(k, _mm256_cmp_ps(_mm256_loadu_ps(row + x - 1), v, _CMP_NGE_UQ));
    k = _mm256_and_ps(k, _mm256_cmp_ps(_mm256_loadu_ps(row + x + 1), v, _CMP_NGT_UQ));
    k = _mm256_and_ps(k, _mm256_cmp_ps(_mm256_loadu_ps(earlier_y + x), v, _CMP_NGE_UQ));
    k = _mm256_and_ps(k, _mm256_cmp_ps(_mm256_loadu_ps(later_y + x), v, _CMP_NGT_UQ));
    k = _mm256_and_ps(k, _mm256_cmp_ps(_mm256_loadu_ps(earlier_z + x), v, _CMP_NGE_UQ));
    k = _mm256_and_ps(k, _mm256_cmp_ps(_mm256_loadu_ps(later_z + x), v, _CMP_NGT_UQ));
    keep |= unsigned(_mm256_movemask_ps(k)) << x;
  }
  return keep;
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
  // Neighbour steps (dx, dy, dz), the 6 faces first: most voxels are rejected by one of them. A
  // step is "earlier" when its offset in the array, unwrapped, is negative.
  std::array<std::array<int, 3>, 26> step;
  std::array<bool, 26> earlier;
  int o = 0;
  for (int pass = 0; pass < 2; ++pass)
    for (int dz = -1; dz <= 1; ++dz)
      for (int dy = -1; dy <= 1; ++dy)
        for (int dx = -1; dx <= 1; ++dx) {
          const int nonzero = (dx != 0) + (dy != 0) + (dz != 0);
          if (nonzero == 0 || (nonzero == 1) != (pass == 0)) continue;
          earlier[o] = (std::ptrdiff_t(dz) * ny + dy) * nx + dx < 0;
          step[o++] = {dx, dy, dz};
        }
  // Strict against earlier neighbours, non-strict against later ones: a plateau yields exactly
  // one maximum, its first voxel. A NaN neighbour beats nothing.
  auto beaten = [](float w, float v, bool earlier) { return earlier ? w >= v : w > v; };
  float threshold = 0;
  // A 16-voxel row's pre-test in one AVX-512 vector, or its inner lanes in two AVX2 ones, where
  // the CPU has them.
  const Isa build = isa();
  // The rows of the current voxel's cyclic neighbourhood: rows[dz + 1][dy + 1].
  const float* rows[3][3];
  // One voxel of the current row: is it a local maximum above the threshold, and among the three
  // highest so far?
  auto visit = [&](int x, int y, int z) {
    const float v = rows[1][1][x];
    // Only values above the third peak so far (or above 0 while fewer than three were found;
    // peaks <= 0 are of no use) need a test.
    if (!(v > threshold)) return;
    const int xs[3] = {wrap(x - 1, nx), x, wrap(x + 1, nx)};
    for (int k = 0; k < 26; ++k)
      if (beaten(rows[step[k][2] + 1][step[k][1] + 1][xs[step[k][0] + 1]], v, earlier[k])) return;
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
    const int zs[3] = {wrap(z - 1, nz), z, wrap(z + 1, nz)};
    for (int y = 0; y < ny; ++y) {
      const int ys[3] = {wrap(y - 1, ny), y, wrap(y + 1, ny)};
      for (int a = 0; a < 3; ++a)
        for (int b = 0; b < 3; ++b) rows[a][b] = corr.data() + index_of(shape, 0, ys[b], zs[a]);
      const float* row = rows[1][1];
      if (nx == 16 && build == Isa::avx512) {
        // The whole row in one vector; its candidates visited in scan order, as below.
        for (unsigned left = row16_candidates_avx512(row, rows[1][0], rows[1][2], rows[0][1], rows[2][1], threshold);
             left; left &= left - 1)
          visit(__builtin_ctz(left), y, z);
        continue;
      }
      if (nx == 16 && build == Isa::avx2) {
        visit(0, y, z);
        for (unsigned left =
                 row16_inner_candidates_avx2(row, rows[1][0], rows[1][2], rows[0][1], rows[2][1], threshold);
             left; left &= left - 1)
          visit(__builtin_ctz(left), y, z);
        visit(15, y, z);
        continue;
      }
      // The row's ends wrap along x; between them, four voxels per SSE comparison: above the
      // threshold and beaten by none of the 6 face neighbours (visit's first tests; most groups
      // hold no such voxel and are passed over with one well-predicted branch). The voxels left
      // are visited in scan order, each tested again (the threshold may have risen), so the
      // result is that of a voxel-by-voxel scan.
      visit(0, y, z);
      int x = 1;
      for (; x + 4 <= nx - 1; x += 4) {
        const __m128 v = _mm_loadu_ps(row + x);
        __m128 keep = _mm_cmpgt_ps(v, _mm_set1_ps(threshold));
        keep = _mm_and_ps(keep, _mm_cmpnge_ps(_mm_loadu_ps(row + x - 1), v));
        keep = _mm_and_ps(keep, _mm_cmpngt_ps(_mm_loadu_ps(row + x + 1), v));
        keep = _mm_and_ps(keep, _mm_cmpnge_ps(_mm_loadu_ps(rows[1][0] + x), v));
        keep = _mm_and_ps(keep, _mm_cmpngt_ps(_mm_loadu_ps(rows[1][2] + x), v));
        keep = _mm_and_ps(keep, _mm_cmpnge_ps(_mm_loadu_ps(rows[0][1] + x), v));
        keep = _mm_and_ps(keep, _mm_cmpngt_ps(_mm_loadu_ps(rows[2][1] + x), v));
        int left = _mm_movemask_ps(keep);
        while (left) {
          visit(x + __builtin_ctz(left), y, z);
          left &= left - 1;
        }
      }
      for (; x < nx - 1; ++x) visit(x, y, z);
      if (nx > 1) visit(nx - 1, y, z);
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
