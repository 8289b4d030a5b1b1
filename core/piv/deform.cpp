// Window deformation: predictor to every voxel, symmetric 7x7x7 windowed-sinc resampling.
#include "core/piv/deform.hpp"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <numbers>

#include "core/base/isa.hpp"

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

// Eight floats: one stencil row and its (zero-weighted) eighth voxel, or one table row and its
// zero. GCC's vector extension, so each target clone gets its own instructions (two SSE or one AVX
// operation per row).
typedef float Lanes8 __attribute__((vector_size(32)));

// Rows for f = -0.5 + r / table_steps, r = 0 .. table_steps: the 7 taps and a zero (one Lanes8).
struct SincTable {
  alignas(32) std::array<std::array<float, sinc_taps + 1>, table_steps + 1> rows{};
  SincTable() {
    for (int r = 0; r <= table_steps; ++r) {
      const double f = -0.5 + double(r) / table_steps;
      double sum = 0;
      std::array<double, sinc_taps> w;
      for (int k = 0; k < sinc_taps; ++k) {
        const double t = f - (k - sinc_taps / 2);
        w[k] = std::abs(t) < hann_half_width ? sinc(t) * (0.5 + 0.5 * std::cos(std::numbers::pi * t / hann_half_width))
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

// Weights for the fractional offset f in [-0.5, 0.5] from the table, linearly interpolated, and a
// zero eighth: each lane rows[r][k] + t (rows[r + 1][k] - rows[r][k]), as a scalar loop would.
[[gnu::always_inline]] inline void weights_from(const SincTable& table, double f, std::array<float, sinc_taps + 1>& w) {
  const auto& rows = table.rows;
  const double u = std::clamp((f + 0.5) * table_steps, 0.0, double(table_steps));
  const int r = std::min(int(u), table_steps - 1);
  const float t = float(u - r);
  Lanes8 low, high;
  std::memcpy(&low, rows[r].data(), sizeof low);
  std::memcpy(&high, rows[r + 1].data(), sizeof high);
  const Lanes8 out = low + t * (high - low);
  std::memcpy(w.data(), &out, sizeof out);
}

// Nearest voxel and weights of a coordinate.
struct Taps {
  int base;                            // first tap: round(p) - 3
  std::array<float, sinc_taps + 1> w;  // the 7 weights and a zero (sum_rows reads rows of 8)
};

[[gnu::always_inline]] inline Taps taps_for(const SincTable& table, double p) {
  Taps t;
  const double n0 = std::floor(p + 0.5);
  t.base = int(n0) - sinc_taps / 2;
  weights_from(table, p - n0, t.w);
  return t;
}

// The taps of one sample along x, y and z.
using Stencil = std::array<Taps, 3>;

// Whether a stencil of `Taps` voxels per axis, its rows read as `RowVoxels` contiguous voxels
// along x (sum_rows), lies inside the volume.
template <int Taps, int RowVoxels, class AnyStencil>
[[gnu::always_inline]] inline bool inside(const std::array<int, 3>& s, const AnyStencil& t) {
  return t[0].base >= 0 && t[0].base + RowVoxels <= s[0] && t[1].base >= 0 && t[1].base + Taps <= s[1] &&
         t[2].base >= 0 && t[2].base + Taps <= s[2];
}
// The sinc's stencil, read as 8 voxels per row (Lanes8).
[[gnu::always_inline]] inline bool inside(const std::array<int, 3>& s, const Stencil& t) {
  return inside<sinc_taps, sinc_taps + 1>(s, t);
}

// N samples inside their volumes (v[n] with stencil t[n]: per axis a first voxel `base` and
// `Taps` weights `w`), summed over the Taps^3 stencil: each of its Taps^2 rows is read as one `Row`
// of contiguous voxels (the sinc's 7 taps as 8, the 8th with weight 0) and added, times its z and
// y weights, into the sample's accumulator; the x weights are applied once at the end. Every lane
// sees the same multiplies and adds in the same order as a scalar loop would (no fused
// multiply-add: deform.cpp is built with -ffp-contract=off), so all target clones and every N give
// the same bits. Why N samples at once: each sample's additions form one dependent chain; N
// independent chains side by side keep the adders busy.
template <int N, int Taps, class Row, class Stencil>
[[gnu::always_inline]] inline void sum_rows(const float* const* v, const std::array<int, 3>& s, const Stencil* t,
                                            float* out) {
  const std::size_t plane = std::size_t(s[0]) * s[1];
  const float* slab[N];
  for (int n = 0; n < N; ++n) slab[n] = v[n] + t[n][2].base * plane + std::size_t(t[n][1].base) * s[0] + t[n][0].base;
  // Each row's weight w_z w_y, computed a Row of y weights at a time (the weight arrays hold a
  // whole Row): in the loop below a weight is one load, not a multiply and a broadcast.
  constexpr int lanes = sizeof(Row) / sizeof(float);
  static_assert(lanes >= Taps && sizeof(t[0][1].w) == sizeof(Row));
  alignas(sizeof(Row)) float wzy[N][Taps][lanes];
  for (int n = 0; n < N; ++n) {
    Row wy;
    std::memcpy(&wy, t[n][1].w.data(), sizeof wy);
    for (int kz = 0; kz < Taps; ++kz) {
      const Row w = t[n][2].w[kz] * wy;
      std::memcpy(wzy[n][kz], &w, sizeof w);
    }
  }
  Row acc[N];
  for (int n = 0; n < N; ++n) acc[n] = Row{};
  for (int kz = 0; kz < Taps; ++kz)
    for (int ky = 0; ky < Taps; ++ky)
      for (int n = 0; n < N; ++n) {
        const float w = wzy[n][kz][ky];
        Row row;
        std::memcpy(&row, slab[n] + kz * plane + std::size_t(ky) * s[0], sizeof row);
        acc[n] += w * row;
      }
  for (int n = 0; n < N; ++n) {
    float total = 0;
    for (int k = 0; k < Taps; ++k) total += t[n][0].w[k] * acc[n][k];
    out[n] = total;
  }
}

// N samples whose stencils may reach past the volume's faces; voxels outside count as 0. Each
// stencil's rows are copied, zeros in place of the voxels outside, into a block of its own and
// summed there by sum_rows: the arithmetic of a stencil inside, as if the volume were padded with
// zeros (a zero adds +-0, which leaves a sum that started at +0 unchanged), so that a sample's
// value does not depend on the path that computed it.
template <int N, int Taps, class Row, class Stencil>
[[gnu::always_inline]] inline void sum_rows_clipped(const float* const* v, const std::array<int, 3>& s,
                                                    const Stencil* t, float* out) {
  constexpr int lanes = sizeof(Row) / sizeof(float);
  const std::size_t plane = std::size_t(s[0]) * s[1];
  alignas(sizeof(Row)) float local[N][Taps][Taps][lanes];
  const float* blocks[N];
  Stencil at_origin[N];
  for (int n = 0; n < N; ++n) {
    // The row's voxels inside the volume: k0 .. k1 - 1 of its `lanes`.
    const int x0 = t[n][0].base, k0 = std::clamp(-x0, 0, lanes), k1 = std::clamp(s[0] - x0, k0, lanes);
    for (int kz = 0; kz < Taps; ++kz)
      for (int ky = 0; ky < Taps; ++ky) {
        const int z = t[n][2].base + kz, y = t[n][1].base + ky;
        float* dst = local[n][kz][ky];
        if (z < 0 || z >= s[2] || y < 0 || y >= s[1]) {
          std::fill(dst, dst + lanes, 0.f);
          continue;
        }
        const float* row = v[n] + z * plane + std::size_t(y) * s[0];
        if (k0 == 0 && k1 == lanes) {
          std::memcpy(dst, row + x0, sizeof(Row));
        } else {
          // Either way zeros beside the voxels inside; per width the form the compiler makes faster.
          if constexpr (lanes > 4) {
            std::fill(dst, dst + lanes, 0.f);
            for (int k = k0; k < k1; ++k) dst[k] = row[x0 + k];
          } else {
            for (int k = 0; k < lanes; ++k) dst[k] = x0 + k >= 0 && x0 + k < s[0] ? row[x0 + k] : 0.f;
          }
        }
      }
    blocks[n] = &local[n][0][0][0];
    at_origin[n] = t[n];
    for (auto& axis : at_origin[n]) axis.base = 0;
  }
  sum_rows<N, Taps, Row>(blocks, {lanes, Taps, Taps}, at_origin, out);
}

// L values of type T as one GCC vector (L floats: one register of the build that takes L lanes).
template <class T, int L>
struct VectorOf {
  typedef T type __attribute__((vector_size(L * sizeof(T))));
};

// The taps along one axis of L samples, lane i holding sample i: its first voxel and its weights.
template <int L, int Taps>
struct TapsAcross {
  alignas(64) int base[L];
  alignas(64) float w[Taps][L];
};

// Whether the M samples in lanes from .. from + M - 1 of t (their taps along x, y and z: t[0],
// t[1], t[2]) can be summed side by side by sum_rows_across: the same y and z taps, x taps starting
// at consecutive voxels, all of them inside the volume.
template <int M, int L, int Taps>
[[gnu::always_inline]] inline bool side_by_side(const std::array<int, 3>& s, const TapsAcross<L, Taps>* t, int from) {
  const int bx = t[0].base[from], by = t[1].base[from], bz = t[2].base[from];
  if (bx < 0 || bx + M - 1 + Taps > s[0] || by < 0 || by + Taps > s[1] || bz < 0 || bz + Taps > s[2]) return false;
  bool same = true;
  for (int i = 1; i < M; ++i)
    same &= t[0].base[from + i] == bx + i && t[1].base[from + i] == by && t[2].base[from + i] == bz;
  return same;
}

// sum_rows for the M samples in lanes from .. from + M - 1 that side_by_side accepts, one vector
// lane per sample: each stencil row is read once per x tap as M contiguous voxels (lane i's tap k
// is voxel base + i + k), where sum_rows reads a row per sample. Lane i sees sum_rows' multiplies
// and adds in sum_rows' order (its z weight times its y weight, per x tap a sum over the rows
// z-major, then the x weights from a sum at +0), so both give a sample the same bits.
template <int M, int L, int Taps>
[[gnu::always_inline]] inline void sum_rows_across(const float* v, const std::array<int, 3>& s,
                                                   const TapsAcross<L, Taps>* t, int from, float* out) {
  using Vec = typename VectorOf<float, M>::type;
  Vec wx[Taps], wy[Taps], wz[Taps];
  for (int k = 0; k < Taps; ++k) {
    std::memcpy(&wx[k], t[0].w[k] + from, sizeof(Vec));
    std::memcpy(&wy[k], t[1].w[k] + from, sizeof(Vec));
    std::memcpy(&wz[k], t[2].w[k] + from, sizeof(Vec));
  }
  const std::size_t plane = std::size_t(s[0]) * s[1];
  const float* first = v + t[2].base[from] * plane + std::size_t(t[1].base[from]) * s[0] + t[0].base[from];
  Vec acc[Taps];
  for (int k = 0; k < Taps; ++k) acc[k] = Vec{};
  for (int kz = 0; kz < Taps; ++kz)
    for (int ky = 0; ky < Taps; ++ky) {
      const Vec w = wz[kz] * wy[ky];
      const float* row = first + kz * plane + std::size_t(ky) * s[0];
      for (int k = 0; k < Taps; ++k) {
        Vec voxels;
        std::memcpy(&voxels, row + k, sizeof voxels);
        acc[k] += w * voxels;
      }
    }
  Vec total = Vec{};
  for (int k = 0; k < Taps; ++k) total += wx[k] * acc[k];
  std::memcpy(out, &total, sizeof total);
}

// Sample i's stencil (sum_rows' layout: per axis its first voxel and weights, zero past the taps)
// from the taps of L samples along x, y and z.
template <class Stencil, int L, int Taps>
[[gnu::always_inline]] inline Stencil stencil_of(const TapsAcross<L, Taps>* t, int i) {
  Stencil out{};
  for (int axis = 0; axis < 3; ++axis) {
    out[axis].base = t[axis].base[i];
    for (int k = 0; k < Taps; ++k) out[axis].w[k] = t[axis].w[k][i];
  }
  return out;
}

// One sample of the sinc anywhere; voxels outside the volume count as 0.
[[gnu::always_inline]] inline float sample(const float* v, const std::array<int, 3>& s, const Stencil& t) {
  float out;
  if (inside(s, t))
    sum_rows<1, sinc_taps, Lanes8>(&v, s, &t, &out);
  else
    sum_rows_clipped<1, sinc_taps, Lanes8>(&v, s, &t, &out);
  return out;
}

using Located = std::pair<int, double>;

typedef double Doubles4 __attribute__((vector_size(32)));
typedef float Floats4 __attribute__((vector_size(16)));

// The predictor's trilinear interpolant in two steps, which NodeField::at and RowPredictor share so
// that both give the same bits: node column i's bilinear value at (y, z) (x, y, z displacement in
// the first three of four lanes, in double), then the linear blend of two columns at fraction fx,
// rounded to float once.
[[gnu::always_inline]] inline void column_at(const NodeField& f, int i, const Located& ly, const Located& lz,
                                             Doubles4& out) {
  const int column = std::min(i, f.count[0] - 1);
  out = Doubles4{0, 0, 0, 0};
  for (int c = 0; c < 4; ++c) {
    const int dy = c & 1, dz = c >> 1;
    const double w = (dy ? ly.second : 1 - ly.second) * (dz ? lz.second : 1 - lz.second);
    const std::size_t k =
        f.index(column, std::min(ly.first + dy, f.count[1] - 1), std::min(lz.first + dz, f.count[2] - 1));
    out += w * Doubles4{f.d[0][k], f.d[1][k], f.d[2][k], 0};
  }
}
[[gnu::always_inline]] inline std::array<float, 3> blend(const Doubles4& low, const Doubles4& high, double fx) {
  const Doubles4 v = (1 - fx) * low + fx * high;
  return {float(v[0]), float(v[1]), float(v[2])};
}

// The predictor along one voxel row (y, z): the two node columns around the current x are kept and
// recomputed only when x enters the next cell (the right one becoming the left one).
class RowPredictor {
 public:
  RowPredictor(const NodeField& f, const Located& ly, const Located& lz) : f_(f), ly_(ly), lz_(lz) {}

  [[gnu::always_inline]] std::array<float, 3> at(const Located& lx) {
    if (lx.first != cell_) {
      if (lx.first == cell_ + 1)
        low_ = high_;
      else
        column_at(f_, lx.first, ly_, lz_, low_);
      column_at(f_, lx.first + 1, ly_, lz_, high_);
      cell_ = lx.first;
    }
    return blend(low_, high_, lx.second);
  }

 private:
  const NodeField& f_;
  Located ly_, lz_;
  int cell_ = -2;  // none yet (-1 would make cell 0 its successor)
  Doubles4 low_ = {0, 0, 0, 0}, high_ = {0, 0, 0, 0};
};

// The 7x7x7 windowed sinc as deform_row's kernel.
struct Sinc7 {
  static constexpr int taps = sinc_taps;
  using Stencil = piv::Stencil;
  const SincTable& table;
  // The taps of L samples at p[0 .. L - 1] along one axis.
  template <int L>
  [[gnu::always_inline]] void across(const double* p, TapsAcross<L, taps>& out) const {
    for (int i = 0; i < L; ++i) {
      const Taps t = taps_for(table, p[i]);
      out.base[i] = t.base;
      for (int k = 0; k < taps; ++k) out.w[k][i] = t.w[k];
    }
  }
  [[gnu::always_inline]] static bool inside(const std::array<int, 3>& s, const Stencil& t) { return piv::inside(s, t); }
  template <int N>
  [[gnu::always_inline]] static void sample_inside(const float* const* v, const std::array<int, 3>& s, const Stencil* t,
                                                   float* out) {
    sum_rows<N, sinc_taps, Lanes8>(v, s, t, out);
  }
  template <int N>
  [[gnu::always_inline]] static void sample_clipped(const float* const* v, const std::array<int, 3>& s,
                                                    const Stencil* t, float* out) {
    sum_rows_clipped<N, sinc_taps, Lanes8>(v, s, t, out);
  }
};

// Keys' cubic convolution (a = -1/2, Catmull-Rom) on the 4 voxels floor(p) - 1 .. floor(p) + 2 per
// axis: a 4x4x4 stencil (16 rows of 4 voxels against the sinc's 49 of 8), exact for quadratics but with more
// phase error near the Nyquist frequency (deform.hpp: Interpolation).
struct Cubic4 {
  static constexpr int taps = 4;
  struct Axis {
    int base;
    std::array<float, taps> w;
  };
  using Stencil = std::array<Axis, 3>;
  // The taps of L samples at p[0 .. L - 1] along one axis, computed side by side: each lane the
  // same double operations, in the same order, as one sample alone.
  template <int L>
  [[gnu::always_inline]] static void across(const double* p, TapsAcross<L, taps>& out) {
    using Doubles = typename VectorOf<double, L>::type;
    using Floats = typename VectorOf<float, L>::type;
    using Ints = typename VectorOf<int, L>::type;
    Doubles at, f0;
    std::memcpy(&at, p, sizeof at);
    for (int i = 0; i < L; ++i) f0[i] = std::floor(p[i]);
    // K(t) = 1.5|t|^3 - 2.5|t|^2 + 1 on |t| <= 1, -0.5|t|^3 + 2.5|t|^2 - 4|t| + 2 on 1 < |t| < 2,
    // at the distances 1 + f, f, g = 1 - f and 1 + g of the voxels floor(p) - 1 .. floor(p) + 2.
    const Doubles f = at - f0, g = 1 - f;
    const Floats w[taps] = {
        __builtin_convertvector(((-0.5 * f + 1) * f - 0.5) * f, Floats),
        __builtin_convertvector((1.5 * f - 2.5) * f * f + 1, Floats),
        __builtin_convertvector((1.5 * g - 2.5) * g * g + 1, Floats),
        __builtin_convertvector(((-0.5 * g + 1) * g - 0.5) * g, Floats),
    };
    const Ints base = __builtin_convertvector(f0, Ints) - 1;
    std::memcpy(out.base, &base, sizeof base);
    for (int k = 0; k < taps; ++k) std::memcpy(out.w[k], &w[k], sizeof w[k]);
  }
  [[gnu::always_inline]] static bool inside(const std::array<int, 3>& s, const Stencil& t) {
    return piv::inside<taps, taps>(s, t);
  }
  template <int N>
  [[gnu::always_inline]] static void sample_inside(const float* const* v, const std::array<int, 3>& s, const Stencil* t,
                                                   float* out) {
    sum_rows<N, taps, Floats4>(v, s, t, out);
  }
  template <int N>
  [[gnu::always_inline]] static void sample_clipped(const float* const* v, const std::array<int, 3>& s,
                                                    const Stencil* t, float* out) {
    sum_rows_clipped<N, taps, Floats4>(v, s, t, out);
  }
};

// Voxels per block of deform_row's per-sample path: 2 x 4 samples side by side (sum_rows says why).
constexpr int block_voxels = 4;

// Both volumes' `count` (<= M) voxels whose taps are lanes from .. from + M - 1 of `taps` (A's,
// then B's, per axis), into a_out and b_out (offset to lane 0): summed across the voxels where
// their stencils lie side by side (a smooth predictor whose rounding does not change across them,
// away from the faces), else as two halves, down to block_voxels voxels summed sample by sample
// (sum_rows, four voxels of both volumes at a time). Every path gives a sample the same bits.
template <int M, int L, class Kernel>
[[gnu::always_inline]] inline void deform_lanes(const float* a, const float* b, const std::array<int, 3>& shape,
                                                const TapsAcross<L, Kernel::taps> (&taps)[2][3], int from, int count,
                                                float* a_out, float* b_out) {
  if (count == M && side_by_side<M>(shape, taps[0], from) && side_by_side<M>(shape, taps[1], from)) {
    sum_rows_across<M>(a, shape, taps[0], from, a_out + from);
    sum_rows_across<M>(b, shape, taps[1], from, b_out + from);
    return;
  }
  if constexpr (M > block_voxels) {
    constexpr int half = M / 2;
    deform_lanes<half, L, Kernel>(a, b, shape, taps, from, std::min(count, half), a_out, b_out);
    if (count > half) deform_lanes<half, L, Kernel>(a, b, shape, taps, from + half, count - half, a_out, b_out);
  } else {
    constexpr int samples = 2 * block_voxels;
    const float* const src[samples] = {a, b, a, b, a, b, a, b};
    static_assert(samples == 8);
    typename Kernel::Stencil t[samples];  // a, b of voxel `from`, then of from + 1, ...
    for (int i = 0; i < count; ++i)
      for (int v = 0; v < 2; ++v) t[2 * i + v] = stencil_of<typename Kernel::Stencil>(taps[v], from + i);
    bool all_inside = count == block_voxels;
    for (int k = 0; k < 2 * count && all_inside; ++k) all_inside = Kernel::inside(shape, t[k]);
    // A stencil past a face is summed from a zero-padded copy (sum_rows_clipped), with the same
    // arithmetic, so either path gives a sample the same bits.
    float out[samples];
    if (all_inside) {
      Kernel::template sample_inside<samples>(src, shape, t, out);
    } else if (count == block_voxels) {
      Kernel::template sample_clipped<samples>(src, shape, t, out);
    } else {
      for (int k = 0; k < 2 * count; ++k) Kernel::template sample_clipped<1>(src + k, shape, t + k, out + k);
    }
    for (int i = 0; i < count; ++i) {
      a_out[from + i] = out[2 * i];
      b_out[from + i] = out[2 * i + 1];
    }
  }
}

// One row (y, z) of both deformed volumes with `kernel`, L voxels at a time (L a multiple of
// block_voxels: the lanes of the build's widest register; deform_lanes sums them). `lx`: the
// predictor's node location of every x; `ly`, `lz`: of this row.
template <int L, class Kernel>
[[gnu::always_inline]] inline void deform_row_with(const Kernel& kernel, const float* a, const float* b,
                                                   const std::array<int, 3>& shape, const NodeField& predictor,
                                                   const Located* lx, const Located& ly, const Located& lz, int y,
                                                   int z, float* a_out, float* b_out) {
  static_assert(L % block_voxels == 0);
  RowPredictor predicted(predictor, ly, lz);
  for (int x0 = 0; x0 < shape[0]; x0 += L) {
    const int n = std::min(L, shape[0] - x0);
    // Each voxel's sample coordinates in A (x - d/2) and B (x + d/2); lanes past the row's end at 0.
    alignas(64) double at[2][3][L];
    for (int i = 0; i < n; ++i) {
      const int x = x0 + i;
      const auto d = predicted.at(lx[x]);
      const double hx = 0.5 * d[0], hy = 0.5 * d[1], hz = 0.5 * d[2];
      at[0][0][i] = x - hx, at[0][1][i] = y - hy, at[0][2][i] = z - hz;
      at[1][0][i] = x + hx, at[1][1][i] = y + hy, at[1][2][i] = z + hz;
    }
    for (int i = n; i < L; ++i)
      for (int v = 0; v < 2; ++v)
        for (int axis = 0; axis < 3; ++axis) at[v][axis][i] = 0;
    TapsAcross<L, Kernel::taps> taps[2][3];  // of A's samples, then of B's; per axis
    for (int v = 0; v < 2; ++v)
      for (int axis = 0; axis < 3; ++axis) kernel.template across<L>(at[v][axis], taps[v][axis]);
    deform_lanes<L, L, Kernel>(a, b, shape, taps, 0, n, a_out + x0, b_out + x0);
  }
}

// deform_row_with for each kernel, built once per instruction set; deform_row picks the build
// isa() names (core/base/isa.hpp).
struct RowJob {
  const float *a, *b;
  const std::array<int, 3>& shape;
  const NodeField& predictor;
  const Located *lx, &ly, &lz;
  int y, z;
  float *a_out, *b_out;
};
template <int L, class Kernel>
[[gnu::always_inline]] inline void deform_row_job(const Kernel& kernel, const RowJob& j) {
  deform_row_with<L>(kernel, j.a, j.b, j.shape, j.predictor, j.lx, j.ly, j.lz, j.y, j.z, j.a_out, j.b_out);
}
__attribute__((target("avx512f"))) void sinc_row_avx512(const SincTable& table, const RowJob& j) {
  deform_row_job<16>(Sinc7{table}, j);
}
__attribute__((target("avx2"))) void sinc_row_avx2(const SincTable& table, const RowJob& j) {
  deform_row_job<8>(Sinc7{table}, j);
}
void sinc_row_baseline(const SincTable& table, const RowJob& j) { deform_row_job<4>(Sinc7{table}, j); }
__attribute__((target("avx512f"))) void cubic_row_avx512(const RowJob& j) { deform_row_job<16>(Cubic4{}, j); }
__attribute__((target("avx2"))) void cubic_row_avx2(const RowJob& j) { deform_row_job<8>(Cubic4{}, j); }
void cubic_row_baseline(const RowJob& j) { deform_row_job<4>(Cubic4{}, j); }

// One row of both deformed volumes: the 7x7x7 sinc with `table`, or without it Keys' cubic.
void deform_row(const SincTable* table, const RowJob& j) {
  if (table) return for_isa(sinc_row_avx512, sinc_row_avx2, sinc_row_baseline)(*table, j);
  for_isa(cubic_row_avx512, cubic_row_avx2, cubic_row_baseline)(j);
}

}  // namespace

NodeField::NodeField(std::array<int, 3> n, std::array<double, 3> first_node, std::array<double, 3> node_step)
    : count(n), first(first_node), step(node_step) {
  for (auto& c : d) c.assign(size(), 0.f);
}

std::pair<int, double> NodeField::locate(int axis, double p) const {
  const double u = std::clamp((p - first[axis]) / step[axis], 0.0, double(count[axis] - 1));
  const int i0 = std::min(int(u), std::max(count[axis] - 2, 0));
  return {i0, count[axis] > 1 ? u - i0 : 0.0};
}

std::array<float, 3> NodeField::at(double x, double y, double z) const {
  const Located lx = locate(0, x), ly = locate(1, y), lz = locate(2, z);
  Doubles4 low, high;
  column_at(*this, lx.first, ly, lz, low);
  column_at(*this, lx.first + 1, ly, lz, high);
  return blend(low, high, lx.second);
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
  std::array<float, sinc_taps + 1> padded;
  weights_from(sinc_table(), f, padded);
  std::copy_n(padded.begin(), sinc_taps, w.begin());
}

float sample_sinc7(std::span<const float> volume, const std::array<int, 3>& shape, double x, double y, double z) {
  const SincTable& table = sinc_table();
  return sample(volume.data(), shape, {taps_for(table, x), taps_for(table, y), taps_for(table, z)});
}

namespace {

// One [1 2 1] / 4 pass along `axis`, src -> dst; at a face the kernel's inner taps only,
// renormalised. Parallel over z-slices.
void binomial_pass(const float* s, float* d, const std::array<int, 3>& shape, int axis) {
  const std::array<std::size_t, 3> stride{1, std::size_t(shape[0]), std::size_t(shape[0]) * shape[1]};
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

}  // namespace

void binomial_smooth(std::span<const float> in, const std::array<int, 3>& shape, std::span<float> out,
                     std::span<float> scratch, int depth_passes) {
  // x: in -> out, y: out -> scratch, z: scratch -> out; then the depth passes, out -> scratch ->
  // out in turn, and a copy home after an odd number of them.
  binomial_pass(in.data(), out.data(), shape, 0);
  binomial_pass(out.data(), scratch.data(), shape, 1);
  binomial_pass(scratch.data(), out.data(), shape, 2);
  for (int k = 0; k < depth_passes; ++k)
    binomial_pass(k % 2 ? scratch.data() : out.data(), k % 2 ? out.data() : scratch.data(), shape, 2);
  if (depth_passes % 2) std::copy(scratch.begin(), scratch.begin() + std::ptrdiff_t(out.size()), out.begin());
}

float subtract_mean_floor(std::span<const float> in, const std::array<int, 3>& shape, double multiple,
                          std::span<float> out) {
  const std::size_t slice = std::size_t(shape[0]) * std::size_t(shape[1]);
  std::vector<double> slice_sums(std::size_t(shape[2]), 0.0);
  tbb::parallel_for(tbb::blocked_range<int>(0, shape[2]), [&](const tbb::blocked_range<int>& r) {
    for (int z = r.begin(); z < r.end(); ++z) {
      double s = 0;
      for (std::size_t i = std::size_t(z) * slice, end = i + slice; i < end; ++i) s += in[i];
      slice_sums[std::size_t(z)] = s;
    }
  });
  double total = 0;
  for (double s : slice_sums) total += s;
  const std::size_t n = slice * std::size_t(shape[2]);
  const float floor = n > 0 ? float(multiple * total / double(n)) : 0.f;
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n, std::size_t(1) << 16),
                    [&](const tbb::blocked_range<std::size_t>& r) {
                      for (std::size_t i = r.begin(); i != r.end(); ++i) out[i] = std::max(0.f, in[i] - floor);
                    });
  return floor;
}

void deform_pair(std::span<const float> a, std::span<const float> b, const std::array<int, 3>& shape,
                 const NodeField& predictor, std::span<float> a_out, std::span<float> b_out,
                 Interpolation interpolation) {
  const std::size_t plane = std::size_t(shape[0]) * shape[1];
  const SincTable& table = sinc_table();
  std::array<std::vector<Located>, 3> where;
  for (int axis = 0; axis < 3; ++axis)
    for (int i = 0; i < shape[axis]; ++i) where[axis].push_back(predictor.locate(axis, i));
  tbb::parallel_for(tbb::blocked_range<int>(0, shape[2]), [&](const tbb::blocked_range<int>& r) {
    for (int z = r.begin(); z < r.end(); ++z)
      for (int y = 0; y < shape[1]; ++y) {
        const std::size_t row = z * plane + std::size_t(y) * shape[0];
        deform_row(interpolation == Interpolation::cubic ? nullptr : &table,
                   {a.data(), b.data(), shape, predictor, where[0].data(), where[1][y], where[2][z], y, z,
                    a_out.data() + row, b_out.data() + row});
      }
  });
}

}  // namespace plenopiv::piv
