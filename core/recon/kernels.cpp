// The reconstruction's vector micro-kernels: the passes' x stages over row lanes, their y stages
// over each visit's row sums, and the row-major quad dot products of the eq 13 normalisers, each
// built for several instruction sets (GCC's target attribute), the build chosen per call by isa()
// (core/base/isa.hpp).
#include "core/recon/kernels.hpp"

#include <immintrin.h>

#include <algorithm>

#include "core/base/isa.hpp"

namespace plenopiv::recon::kernels {
namespace {

// Row-major dot products over quads, for the eq 13 normalisers (one sensor row against every
// voxel x of a slice), in two builds: the baseline x86-64 one works one quad (one SSE vector) at
// a time; the AVX2 one pairs two quads in one 8-lane vector. Both do the same float operations
// in the same order (a multiply, then an add), so they give the same bits; the passes' x stages
// use the same order per row.
using Lanes8 = float __attribute__((vector_size(32)));

__attribute__((target("avx2"), always_inline)) inline Lanes8 load_pair(const float* lo, const float* hi) {
  Lanes4 a, b;
  __builtin_memcpy(&a, lo, sizeof a);
  __builtin_memcpy(&b, hi, sizeof b);
  return __builtin_shufflevector(a, b, 0, 1, 2, 3, 4, 5, 6, 7);
}
__attribute__((target("avx2"), always_inline)) inline Lanes8 load8(const float* p) {
  Lanes8 v;
  __builtin_memcpy(&v, p, sizeof v);
  return v;
}

// Σ_k Σ_j w[4 k + j] row[first[k] + j], in two vector
// accumulators (even and odd quads) so consecutive adds do not wait on each other; a fixed order.
inline float dot_quads_base(const float* row, const int* first, const float* w, std::size_t n) {
  float even[kQuad] = {0.f, 0.f, 0.f, 0.f}, odd[kQuad] = {0.f, 0.f, 0.f, 0.f};
  std::size_t k = 0;
  for (; k + 2 <= n; k += 2) {
    const float* p0 = row + first[k];
    const float* p1 = row + first[k + 1];
    const float* w0 = w + kQuad * k;
    for (int j = 0; j < kQuad; ++j) {
      even[j] += w0[j] * p0[j];
      odd[j] += w0[kQuad + j] * p1[j];
    }
  }
  if (k < n) {
    const float* p0 = row + first[k];
    const float* w0 = w + kQuad * k;
    for (int j = 0; j < kQuad; ++j) even[j] += w0[j] * p0[j];
  }
  // Lanes added as one vector, then pairwise: the same order as adding them one by one.
  float lane[kQuad];
  for (int j = 0; j < kQuad; ++j) lane[j] = even[j] + odd[j];
  return (lane[0] + lane[1]) + (lane[2] + lane[3]);
}
// The same sums: the even quads in lanes 0-3, the odd ones in lanes 4-7.
__attribute__((target("avx2"), always_inline)) inline float dot_quads_avx2(const float* row, const int* first,
                                                                           const float* w, std::size_t n) {
  Lanes8 acc = {0.f, 0.f, 0.f, 0.f, 0.f, 0.f, 0.f, 0.f};
  std::size_t k = 0;
  for (; k + 2 <= n; k += 2) acc += load8(w + kQuad * k) * load_pair(row + first[k], row + first[k + 1]);
  Lanes4 even = __builtin_shufflevector(acc, acc, 0, 1, 2, 3);
  const Lanes4 odd = __builtin_shufflevector(acc, acc, 4, 5, 6, 7);
  if (k < n) {
    Lanes4 p, wk;
    __builtin_memcpy(&p, row + first[k], sizeof p);
    __builtin_memcpy(&wk, w + kQuad * k, sizeof wk);
    even += wk * p;
  }
  const Lanes4 lane = even + odd;
  return (lane[0] + lane[1]) + (lane[2] + lane[3]);
}

// The same for two rows at once, each with dot_quads_avx2's sums in its order.
__attribute__((target("avx2"), always_inline)) inline void dot_quads2_avx2(const float* row_a, const float* row_b,
                                                                           const int* first, const float* w,
                                                                           std::size_t n, float* out_a, float* out_b) {
  Lanes8 acc_a = {0.f, 0.f, 0.f, 0.f, 0.f, 0.f, 0.f, 0.f}, acc_b = acc_a;
  std::size_t k = 0;
  for (; k + 2 <= n; k += 2) {
    const int f0 = first[k], f1 = first[k + 1];
    const Lanes8 wk = load8(w + kQuad * k);
    acc_a += wk * load_pair(row_a + f0, row_a + f1);
    acc_b += wk * load_pair(row_b + f0, row_b + f1);
  }
  Lanes4 even_a = __builtin_shufflevector(acc_a, acc_a, 0, 1, 2, 3),
         even_b = __builtin_shufflevector(acc_b, acc_b, 0, 1, 2, 3);
  const Lanes4 odd_a = __builtin_shufflevector(acc_a, acc_a, 4, 5, 6, 7),
               odd_b = __builtin_shufflevector(acc_b, acc_b, 4, 5, 6, 7);
  if (k < n) {
    Lanes4 pa, pb, wk;
    __builtin_memcpy(&pa, row_a + first[k], sizeof pa);
    __builtin_memcpy(&pb, row_b + first[k], sizeof pb);
    __builtin_memcpy(&wk, w + kQuad * k, sizeof wk);
    even_a += wk * pa;
    even_b += wk * pb;
  }
  const Lanes4 lane_a = even_a + odd_a, lane_b = even_b + odd_b;
  *out_a = (lane_a[0] + lane_a[1]) + (lane_a[2] + lane_a[3]);
  *out_b = (lane_b[0] + lane_b[1]) + (lane_b[2] + lane_b[3]);
}

using Rows = float __attribute__((vector_size(kSubRows * sizeof(float))));

// The x stages multiply a quad's zero lanes (its padding, inside the row) like the others: each
// adds ±0 (its pixel or row sum being finite) to a sum that started at +0 and so is never -0,
// which leaves the sum's bits as skipping the lane would, without a compare and a branch per weight.

// Projection stage 2 (add_columns in kernels.hpp), in every build.
[[gnu::always_inline]] inline void add_columns_body(float* band, std::size_t width, int words, const ColumnJob* jobs,
                                                    int count) {
  for (int word = 0; word < words; ++word) {
    for (int sub = 0; sub < 64; sub += kSubRows) {
      float* block = band + std::size_t(64 * word + sub) * width;
      for (int v = 0; v < count; ++v) {
        const ColumnJob& j = jobs[v];
        if (((j.rows[word] >> sub) & kSubMask) == 0) continue;
        float* g = j.sums + 64 * word + sub;
        Rows gv;
        __builtin_memcpy(&gv, g, sizeof gv);
        std::fill_n(g, kSubRows, 0.f);
        for (std::size_t k = 0; k < j.n; ++k) {
          float* at = block + std::size_t(j.first[k]) * kSubRows;
          const float* w = j.w + kQuad * k;
#pragma GCC unroll 4
          for (int l = 0; l < kQuad; ++l) {
            Rows p;
            __builtin_memcpy(&p, at + l * kSubRows, sizeof p);
            p += gv * w[l];
            __builtin_memcpy(at + l * kSubRows, &p, sizeof p);
          }
        }
      }
    }
  }
}

// Back-projection stage 1 (dot_columns in kernels.hpp) on R of a block's kSubRows rows at a time,
// R floats being one vector register of the build: its eight accumulators (lane j of the even
// quads and of the odd ones) then stay in registers (16 rows at once would need all sixteen of
// AVX2's and spill). Each row's sum in dot_quads_base's order, then even + odd and the lanes
// pairwise: the same operations per row whatever R.
template <int R>
struct RowPart;  // R rows of a block: their floats and a mask
template <>
struct RowPart<4> {
  using F = float __attribute__((vector_size(16)));
  using I = std::int32_t __attribute__((vector_size(16)));
};
template <>
struct RowPart<8> {
  using F = float __attribute__((vector_size(32)));
  using I = std::int32_t __attribute__((vector_size(32)));
};
template <>
struct RowPart<16> {
  using F = float __attribute__((vector_size(64)));
  using I = std::int32_t __attribute__((vector_size(64)));
};

template <int R>
__attribute__((always_inline)) inline void dot_columns_rows(const float* band, std::size_t width, int words,
                                                            const ColumnJob* jobs, int count) {
  static_assert(kSubRows % R == 0);
  using Part = typename RowPart<R>::F;
  using PartBits = typename RowPart<R>::I;
  const auto dot_part = [](Part* acc, const float* at, const float* w) {
#pragma GCC unroll 4
    for (int l = 0; l < kQuad; ++l) {
      Part p;
      __builtin_memcpy(&p, at + l * kSubRows, sizeof p);
      acc[l] += p * w[l];
    }
  };
  PartBits lane_bit;
  for (int l = 0; l < R; ++l) lane_bit[l] = 1 << l;
  for (int word = 0; word < words; ++word) {
    for (int sub = 0; sub < 64; sub += kSubRows) {
      const float* lanes = band + std::size_t(64 * word + sub) * width;
      for (int v = 0; v < count; ++v) {
        const ColumnJob& j = jobs[v];
        const std::int32_t bits = std::int32_t((j.rows[word] >> sub) & kSubMask);
        if (bits == 0) continue;
        for (int h = 0; h < kSubRows; h += R) {
          const PartBits reached = (PartBits{} + (bits >> h)) & lane_bit;
          Part even[kQuad] = {}, odd[kQuad] = {};
          std::size_t k = 0;
          for (; k + 2 <= j.n; k += 2) {
            dot_part(even, lanes + std::size_t(j.first[k]) * kSubRows + h, j.w + kQuad * k);
            dot_part(odd, lanes + std::size_t(j.first[k + 1]) * kSubRows + h, j.w + kQuad * (k + 1));
          }
          if (k < j.n) dot_part(even, lanes + std::size_t(j.first[k]) * kSubRows + h, j.w + kQuad * k);
          const Part lane0 = even[0] + odd[0], lane1 = even[1] + odd[1];
          const Part lane2 = even[2] + odd[2], lane3 = even[3] + odd[3];
          const Part sum = (lane0 + lane1) + (lane2 + lane3);
          const Part kept = reached != 0 ? sum : Part{};
          __builtin_memcpy(j.sums + 64 * word + sub + h, &kept, sizeof kept);
        }
      }
    }
  }
}

// Projection stage 1 (add_rows in kernels.hpp), in every build.
[[gnu::always_inline]] inline void add_rows_body(const RowJob* jobs, int count, int r0, const float* scaled) {
  for (int v = 0; v < count; ++v) {
    const RowJob& j = jobs[v];
    for (std::size_t k = 0; k < j.n; ++k) {
      const BandEntry& entry = j.entries[k];
      const float s = scaled[entry.position];
      if (s == 0.f) continue;
      const int* first = j.first + entry.quad_begin;
      const float* w = j.w + kQuad * std::size_t(entry.quad_begin);
      for (std::uint32_t q = 0; q < entry.quad_count; ++q) {
        float* g = j.sums + (first[q] - r0);
        const float* wq = w + kQuad * q;
        Lanes4 sum, wv;
        __builtin_memcpy(&sum, g, sizeof sum);
        __builtin_memcpy(&wv, wq, sizeof wv);
        sum += s * wv;
        __builtin_memcpy(g, &sum, sizeof sum);
      }
    }
  }
}

// Back-projection stage 2 (dot_rows in kernels.hpp): one entry's sum from +0, quad after quad
// and lane after lane (products of floats, exact in double): the baseline build's whole loop, and
// the others' entries left over from their groups of four.
[[gnu::always_inline]] inline double dot_entry(const RowJob& j, int r0, const BandEntry& entry) {
  double s = 0;
  for (std::uint32_t q = 0; q < entry.quad_count; ++q) {
    const std::uint32_t at = entry.quad_begin + q;
    Lanes4 wq, bq;
    __builtin_memcpy(&wq, j.w + kQuad * std::size_t(at), sizeof wq);
    __builtin_memcpy(&bq, j.sums + (j.first[at] - r0), sizeof bq);
    const Doubles4 p = __builtin_convertvector(wq, Doubles4) * __builtin_convertvector(bq, Doubles4);
    s = (((s + p[0]) + p[1]) + p[2]) + p[3];
  }
  return s;
}
void dot_rows_baseline(const RowJob* jobs, int count, int r0, double* sums, std::uint32_t first) {
  for (int v = 0; v < count; ++v) {
    const RowJob& j = jobs[v];
    for (std::size_t k = 0; k < j.n; ++k) sums[j.entries[k].position - first] += dot_entry(j, r0, j.entries[k]);
  }
}
// The AVX2 and AVX-512 builds: four entries at a time, one per lane of a vector of doubles, so
// that four chains of dependent adds run side by side. Per quad step each entry's four products
// (one vector per entry) are transposed into one vector per quad lane and added lane after lane:
// every entry gets its additions in dot_entry's order. An entry past its last quad adds 0 times
// a row sum of its last quad (finite): +-0, which leaves its sum (never -0) as it was.
__attribute__((target("avx2"), always_inline)) inline void dot_rows_x4(const RowJob* jobs, int count, int r0,
                                                                       double* sums, std::uint32_t first) {
  static constexpr float kZeroQuad[kQuad] = {};
  for (int v = 0; v < count; ++v) {
    const RowJob& j = jobs[v];
    std::size_t k = 0;
    for (; k + 4 <= j.n; k += 4) {
      const BandEntry* e = j.entries + k;
      const std::uint32_t most =
          std::max(std::max(e[0].quad_count, e[1].quad_count), std::max(e[2].quad_count, e[3].quad_count));
      __m256d sum = _mm256_setzero_pd();
      for (std::uint32_t q = 0; q < most; ++q) {
        __m256d p[4];
#pragma GCC unroll 4
        for (int i = 0; i < 4; ++i) {
          const bool in = q < e[i].quad_count;
          const std::uint32_t at = e[i].quad_begin + (in ? q : e[i].quad_count - 1);
          const float* w = in ? j.w + kQuad * std::size_t(at) : kZeroQuad;
          p[i] = _mm256_mul_pd(_mm256_cvtps_pd(_mm_loadu_ps(w)),
                               _mm256_cvtps_pd(_mm_loadu_ps(j.sums + (j.first[at] - r0))));
        }
        const __m256d lo01 = _mm256_unpacklo_pd(p[0], p[1]);  // p0[0] p1[0] p0[2] p1[2]
        const __m256d hi01 = _mm256_unpackhi_pd(p[0], p[1]);  // p0[1] p1[1] p0[3] p1[3]
        const __m256d lo23 = _mm256_unpacklo_pd(p[2], p[3]);
        const __m256d hi23 = _mm256_unpackhi_pd(p[2], p[3]);
        sum = _mm256_add_pd(sum, _mm256_permute2f128_pd(lo01, lo23, 0x20));
        sum = _mm256_add_pd(sum, _mm256_permute2f128_pd(hi01, hi23, 0x20));
        sum = _mm256_add_pd(sum, _mm256_permute2f128_pd(lo01, lo23, 0x31));
        sum = _mm256_add_pd(sum, _mm256_permute2f128_pd(hi01, hi23, 0x31));
      }
      alignas(32) double lane[4];
      _mm256_store_pd(lane, sum);
#pragma GCC unroll 4
      for (int i = 0; i < 4; ++i) sums[e[i].position - first] += lane[i];
    }
    for (; k < j.n; ++k) sums[j.entries[k].position - first] += dot_entry(j, r0, j.entries[k]);
  }
}

__attribute__((target("avx512f"))) void add_rows_avx512(const RowJob* jobs, int count, int r0, const float* scaled) {
  add_rows_body(jobs, count, r0, scaled);
}
__attribute__((target("avx2"))) void add_rows_avx2(const RowJob* jobs, int count, int r0, const float* scaled) {
  add_rows_body(jobs, count, r0, scaled);
}
void add_rows_baseline(const RowJob* jobs, int count, int r0, const float* scaled) {
  add_rows_body(jobs, count, r0, scaled);
}
__attribute__((target("avx512f"))) void dot_rows_avx512(const RowJob* jobs, int count, int r0, double* sums,
                                                        std::uint32_t first) {
  dot_rows_x4(jobs, count, r0, sums, first);
}
__attribute__((target("avx2"))) void dot_rows_avx2(const RowJob* jobs, int count, int r0, double* sums,
                                                   std::uint32_t first) {
  dot_rows_x4(jobs, count, r0, sums, first);
}

__attribute__((target("avx512f"))) void add_columns_avx512(float* band, std::size_t width, int words,
                                                           const ColumnJob* jobs, int count) {
  add_columns_body(band, width, words, jobs, count);
}
__attribute__((target("avx2"))) void add_columns_avx2(float* band, std::size_t width, int words, const ColumnJob* jobs,
                                                      int count) {
  add_columns_body(band, width, words, jobs, count);
}
void add_columns_baseline(float* band, std::size_t width, int words, const ColumnJob* jobs, int count) {
  add_columns_body(band, width, words, jobs, count);
}

void dot_columns_baseline(const float* band, std::size_t width, int words, const ColumnJob* jobs, int count) {
  dot_columns_rows<4>(band, width, words, jobs, count);
}
__attribute__((target("avx2"))) void dot_columns_avx2(const float* band, std::size_t width, int words,
                                                      const ColumnJob* jobs, int count) {
  dot_columns_rows<8>(band, width, words, jobs, count);
}
__attribute__((target("avx512f"))) void dot_columns_avx512(const float* band, std::size_t width, int words,
                                                           const ColumnJob* jobs, int count) {
  dot_columns_rows<16>(band, width, words, jobs, count);
}

// The eq 13 normalisers' first stage (dot_slice_rows in kernels.hpp) in two hand-written builds.
void dot_slice_rows_baseline(const float* row_a, const float* row_b, const std::size_t* start, const int* first,
                             const float* w, int nx, double* out_a, double* out_b) {
  for (int x = 0; x < nx; ++x) {
    const std::size_t q0 = start[x], n = start[x + 1] - q0;
    out_a[x] = dot_quads_base(row_a, first + q0, w + kQuad * q0, n);
    if (row_b) out_b[x] = dot_quads_base(row_b, first + q0, w + kQuad * q0, n);
  }
}
__attribute__((target("avx2"))) void dot_slice_rows_avx2(const float* row_a, const float* row_b,
                                                         const std::size_t* start, const int* first, const float* w,
                                                         int nx, double* out_a, double* out_b) {
  for (int x = 0; x < nx; ++x) {
    const std::size_t q0 = start[x], n = start[x + 1] - q0;
    if (row_b) {
      float a, b;
      dot_quads2_avx2(row_a, row_b, first + q0, w + kQuad * q0, n, &a, &b);
      out_a[x] = a;
      out_b[x] = b;
    } else {
      out_a[x] = dot_quads_avx2(row_a, first + q0, w + kQuad * q0, n);
    }
  }
}

}  // namespace

// `count` image rows from `rows` -> row lanes from `lanes`; the rest of the last block is 0.
void rows_to_lanes(const float* rows, std::size_t width, int count, float* lanes) {
  for (int b0 = 0; b0 < count; b0 += kSubRows) {
    float* block = lanes + std::size_t(b0) * width;
    const int in_block = std::min(kSubRows, count - b0);
    for (std::size_t c0 = 0; c0 < width; c0 += kSubRows) {
      const std::size_t c1 = std::min(width, c0 + kSubRows);
      for (int l = 0; l < in_block; ++l) {
        const float* in = rows + std::size_t(b0 + l) * width;
        for (std::size_t c = c0; c < c1; ++c) block[c * kSubRows + std::size_t(l)] = in[c];
      }
      for (int l = in_block; l < kSubRows; ++l) {
        for (std::size_t c = c0; c < c1; ++c) block[c * kSubRows + std::size_t(l)] = 0.f;
      }
    }
  }
}
// The way back: row lanes from `lanes` -> `count` image rows from `rows`.
void lanes_to_rows(const float* lanes, std::size_t width, int count, float* rows) {
  for (int b0 = 0; b0 < count; b0 += kSubRows) {
    const float* block = lanes + std::size_t(b0) * width;
    const int in_block = std::min(kSubRows, count - b0);
    for (std::size_t c0 = 0; c0 < width; c0 += kSubRows) {
      const std::size_t c1 = std::min(width, c0 + kSubRows);
      for (int l = 0; l < in_block; ++l) {
        float* out = rows + std::size_t(b0 + l) * width;
        for (std::size_t c = c0; c < c1; ++c) out[c] = block[c * kSubRows + std::size_t(l)];
      }
    }
  }
}

void add_columns(float* band, std::size_t width, int words, const ColumnJob* jobs, int count) {
  for_isa(add_columns_avx512, add_columns_avx2, add_columns_baseline)(band, width, words, jobs, count);
}

void dot_columns(const float* band, std::size_t width, int words, const ColumnJob* jobs, int count) {
  for_isa(dot_columns_avx512, dot_columns_avx2, dot_columns_baseline)(band, width, words, jobs, count);
}

void add_rows(const RowJob* jobs, int count, int r0, const float* scaled) {
  for_isa(add_rows_avx512, add_rows_avx2, add_rows_baseline)(jobs, count, r0, scaled);
}

void dot_rows(const RowJob* jobs, int count, int r0, double* sums, std::uint32_t first) {
  for_isa(dot_rows_avx512, dot_rows_avx2, dot_rows_baseline)(jobs, count, r0, sums, first);
}

// The AVX2 build on AVX-512 CPUs too (there is no AVX-512 one).
void dot_slice_rows(const float* row_a, const float* row_b, const std::size_t* start, const int* first, const float* w,
                    int nx, double* out_a, double* out_b) {
  for_isa(dot_slice_rows_avx2, dot_slice_rows_avx2, dot_slice_rows_baseline)(row_a, row_b, start, first, w, nx, out_a,
                                                                             out_b);
}

// 4 pixels per vector (-O2 leaves the plain loop scalar).
void white_band(float* image, const float* white, std::size_t n) {
  std::size_t i = 0;
  for (; i + kQuad <= n; i += kQuad) {
    Lanes4 p, w;
    __builtin_memcpy(&p, image + i, sizeof p);
    __builtin_memcpy(&w, white + i, sizeof w);
    p *= w;
    __builtin_memcpy(image + i, &p, sizeof p);
  }
  for (; i < n; ++i) image[i] *= white[i];
}

}  // namespace plenopiv::recon::kernels
