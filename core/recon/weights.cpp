// The plenoptic weighting function of sec 5.2 (eqs 10-13): separable tables, matrix-free
// operators and the explicit reference matrix, all from the same 1-D ray primitive.
#include "core/recon/weights.hpp"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/partitioner.h>
#include <tbb/task_arena.h>
#include <xmmintrin.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <bit>
#include <cmath>
#include <functional>
#include <limits>
#include <numeric>
#include <string>
#include <utility>

#include "core/base/errors.hpp"

namespace plenopiv::recon {
namespace {

// Interpolation fractions this close to 0 or 1 are rounding noise of an exact hit.
constexpr double kSnap = 1e-9;

struct Hit {
  int index = -1;
  double weight = 0;
};

// Eq 11 in lattice coordinates: the two lenses whose centres bracket `x` and the linear weights
// (1 - t, t). Lattice coordinates are piecewise linear between measured centres; beyond the
// array's ends they continue with the edge pitch and the missing lens's share is lost.
std::pair<Hit, Hit> bracket(const std::vector<double>& centres, double x) {
  const int n = int(centres.size());
  if (n == 1) return {Hit{}, Hit{}};
  const auto it = std::upper_bound(centres.begin(), centres.end(), x);
  const int i1 = int(it - centres.begin());
  if (i1 == 0) {
    const double t = 1.0 + (x - centres[0]) / (centres[1] - centres[0]);
    return {Hit{}, t > 0 ? Hit{0, t} : Hit{}};
  }
  if (i1 == n) {
    const double t = (x - centres[n - 1]) / (centres[n - 1] - centres[n - 2]);
    return {t < 1 ? Hit{n - 1, 1.0 - t} : Hit{}, Hit{}};
  }
  const int i0 = i1 - 1;
  double t = (x - centres[i0]) / (centres[i1] - centres[i0]);
  if (t < kSnap) t = 0;
  if (t > 1 - kSnap) t = 1;
  return {Hit{i0, 1.0 - t}, Hit{i1, t}};
}

// Everything about one ray along one sensor axis: up to 2 lenses x 2 pixels (the 1-D factor of
// eq 12's 16 coefficients). `pixel_of_mm` maps sensor mm to a fractional pixel index.
template <typename PixelOf>
int ray_coefficients(const WeightingOperator::Geometry& g, const std::vector<double>& centres,
                     double alpha, double prime_mm, double u, int pixels, PixelOf pixel_of_mm,
                     int* out_pixel, double* out_weight) {
  // Eq 2: where the ray from aperture point u through the image-space point x' meets the
  // microlens plane.
  const double x_ml = u * (1.0 - 1.0 / alpha) + prime_mm / alpha;
  const auto [a, b] = bracket(centres, x_ml);
  int count = 0;
  for (const Hit& lens : {a, b}) {
    if (lens.index < 0 || lens.weight <= 0) continue;
    // Eq 1 inverted: behind that lens the ray lands at spot - u f_l / s_i.
    const double spot = optics::lens_centre_to_spot_mm(centres[std::size_t(lens.index)], g.s_i, g.f_lens);
    const double p = pixel_of_mm(spot - u * g.f_lens / g.s_i);
    double p0 = std::floor(p);
    double t = p - p0;
    // Rounding must not turn an exact hit into a 1e-16 weight on the neighbour (it would widen
    // the voxel's footprint by a pixel that a dark test would then see).
    if (t < kSnap) t = 0;
    if (t > 1 - kSnap) {
      t = 0;
      p0 += 1;
    }
    const int i0 = int(p0);
    if (i0 >= 0 && i0 < pixels && t < 1) {
      out_pixel[count] = i0;
      out_weight[count++] = lens.weight * (1.0 - t);
    }
    if (i0 + 1 >= 0 && i0 + 1 < pixels && t > 0) {
      out_pixel[count] = i0 + 1;
      out_weight[count++] = lens.weight * t;
    }
  }
  return count;
}

double sample_position(double aperture, int samples, int k) {
  return (k + 0.5) * aperture / samples - 0.5 * aperture;
}

// Pixels per quad: one SSE vector, and at least as long as most segments away from focus (2-4
// pixels behind each lens on the paper's camera beyond 5 mm from focus).
constexpr int kQuad = 4;
// The kernels' x stages take kChunk visits (voxel columns in one band) at a time and walk them
// one block of kSubRows sensor rows at a time: the pixels those visits share in those rows (a
// few KB) stay in L1 instead of being fetched again for every column. Measured on the paper case
// with row-major quads (docs/benchmarks.md): projection 1.1x, back-projection 1.2x less CPU time
// than column by column; 16 x 16 and 8 x 32 did about as well, 16 x 8 worse. kSubRows is also
// the width of the row lanes (below): one AVX-512 register of floats.
constexpr int kChunk = 32;
constexpr int kSubRows = 16;
static_assert(64 % kSubRows == 0 && kSubRows <= 64);

// The kernels' form of one axis's weights: every segment cut into quads of kQuad pixels, voxel
// v owning quads [start[v], start[v + 1]). Along x a quad past the end of the row is shifted left
// and its lanes outside its own pixels weigh 0, so the kernels never touch a pixel outside the
// row (`shift_width`; 0 along y, whose quads weigh rows of the kernels' padded scratch arrays).
// Segments are at least kGap + 1 > kQuad - 1 pixels apart, so the quads of different segments
// never overlap.
void build_quads(const std::vector<WeightRun>& runs, const std::vector<Segment>& segments,
                 const std::vector<float>& table, int shift_width, std::vector<std::size_t>& start,
                 std::vector<int>& quad_first, std::vector<float>& quad_weights) {
  start.assign(runs.size() + 1, 0);
  for (std::size_t v = 0; v < runs.size(); ++v) {
    const WeightRun& run = runs[v];
    for (std::size_t k = run.segment_begin; k < run.segment_end; ++k) {
      const Segment& s = segments[k];
      for (int c = 0; c < s.length; c += kQuad) {
        const int own_first = s.first + c, own_end = s.first + std::min(c + kQuad, s.length);
        const int first = shift_width > 0 ? std::min(own_first, shift_width - kQuad) : own_first;
        quad_first.push_back(first);
        for (int p = first; p < first + kQuad; ++p) {
          quad_weights.push_back(p >= own_first && p < own_end ? table[s.offset + std::size_t(p - s.first)] : 0.f);
        }
      }
    }
    start[v + 1] = quad_first.size();
  }
}

// Row-major dot products over quads, for the eq 13 normalisers (one sensor row against every
// voxel x of a slice), in two builds chosen at run time by GCC's function multiversioning: the
// baseline x86-64 one works one quad (one SSE vector) at a time; the AVX2 one pairs two quads in
// one 8-lane vector. Both do the same float operations in the same order (a multiply, then an
// add), so they give the same bits; the passes' x stages below use the same order per row.
using Lanes4 = float __attribute__((vector_size(16)));
using Lanes8 = float __attribute__((vector_size(32)));
using Doubles4 = double __attribute__((vector_size(32)));

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
  Lanes4 even_a = __builtin_shufflevector(acc_a, acc_a, 0, 1, 2, 3), even_b = __builtin_shufflevector(acc_b, acc_b, 0, 1, 2, 3);
  const Lanes4 odd_a = __builtin_shufflevector(acc_a, acc_a, 4, 5, 6, 7), odd_b = __builtin_shufflevector(acc_b, acc_b, 4, 5, 6, 7);
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

// One visit of a chunk as the x stages see it: its row sums over the band (G for the projection;
// B, per image, for the back-projection; pointing at the band's first row), the band's rows it
// reaches (kRowWords words), and its column's x quads.
struct ColumnJob {
  std::array<float*, 2> sums;
  const std::uint64_t* rows;
  const int* first;
  const float* w;
  std::size_t n;
};
// The job of voxel column x of slice `t` reaching the band rows `rows`, its sums not yet set.
ColumnJob x_job(const SliceTables& t, int x, const std::uint64_t* rows) {
  const std::size_t q0 = t.x_quad_start[std::size_t(x)], q1 = t.x_quad_start[std::size_t(x) + 1];
  return ColumnJob{{nullptr, nullptr}, rows, t.x_quad_first.data() + q0, t.x_quad_weights.data() + kQuad * q0, q1 - q0};
}

// The x stages work on images in "row lanes": each block of kSubRows sensor rows stored column
// by column, the block's kSubRows pixels of one column side by side, so pixel (r, c) is at
// ((r / kSubRows) * width + c) * kSubRows + r % kSubRows. One x weight then meets all of a
// block's rows in one 16-lane vector operation (one AVX-512 register, two AVX2 ones) instead of
// one 4-pixel quad per row: a 16-row block of a visit is on average 13 rows reached on the paper
// case, so the vectors are mostly full.
using Rows = float __attribute__((vector_size(kSubRows * sizeof(float))));
using RowBits = std::int32_t __attribute__((vector_size(kSubRows * sizeof(std::int32_t))));
constexpr std::uint64_t kSubMask = ~std::uint64_t(0) >> (64 - kSubRows);

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

// acc[l] += w[l] · (column l of a quad, kSubRows rows), skipping zero weights.
__attribute__((always_inline)) inline void dot_quad(Rows* acc, const float* at, const float* w) {
#pragma GCC unroll 4
  for (int l = 0; l < kQuad; ++l) {
    if (w[l] == 0.f) continue;
    Rows p;
    __builtin_memcpy(&p, at + l * kSubRows, sizeof p);
    acc[l] += p * w[l];
  }
}

// The dispatched entry points (GCC's function multiversioning, an ifunc resolved once at load
// time, as core/piv/deform.cpp's target_clones): one call per chunk of visits in a band, so the
// loops over blocks, visits and weights run inside the chosen build. Each build does the same
// float operations in the same order on each lane (a multiply, then an add: weights.cpp is built
// with -ffp-contract=off, so the AVX-512 build fuses nothing), so all give the same bits. A zero
// weight (a quad's padding) is skipped: it would add +0.
//
// Projection stage 2: lanes(r, ·) += G(r) Ax over the band's blocks of kSubRows rows that a
// visit reaches, resetting G for later use. `band` points at the band's first block; every
// pixel gets its visits' additions in visiting order, its quads' in quad order.
__attribute__((target_clones("avx512f", "avx2", "default"))) void add_columns(float* band, std::size_t width, int words,
                                                                              const ColumnJob* jobs, int count) {
  for (int word = 0; word < words; ++word) {
    for (int sub = 0; sub < 64; sub += kSubRows) {
      float* block = band + std::size_t(64 * word + sub) * width;
      for (int v = 0; v < count; ++v) {
        const ColumnJob& j = jobs[v];
        if (((j.rows[word] >> sub) & kSubMask) == 0) continue;
        float* g = j.sums[0] + 64 * word + sub;
        Rows gv;
        __builtin_memcpy(&gv, g, sizeof gv);
        std::fill_n(g, kSubRows, 0.f);
        for (std::size_t k = 0; k < j.n; ++k) {
          float* at = block + std::size_t(j.first[k]) * kSubRows;
          const float* w = j.w + kQuad * k;
#pragma GCC unroll 4
          for (int l = 0; l < kQuad; ++l) {
            if (w[l] == 0.f) continue;
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

// Back-projection stage 1: B_i[r] = Σ_col Ax r_i(r, col) over the blocks a visit reaches, for
// `images` (1 or 2) lanes images whose bands start at band[i]; rows the visit does not reach
// keep 0. Each row's sum in dot_quads_base's order: lane j of the even quads and of the odd ones
// in eight accumulators, then even + odd and the lanes pairwise.
__attribute__((target_clones("avx512f", "avx2", "default"))) void dot_columns(const float* const* band, int images,
                                                                              std::size_t width, int words,
                                                                              const ColumnJob* jobs, int count) {
  RowBits lane_bit;
  for (int l = 0; l < kSubRows; ++l) lane_bit[l] = 1 << l;
  for (int word = 0; word < words; ++word) {
    for (int sub = 0; sub < 64; sub += kSubRows) {
      const std::size_t block = std::size_t(64 * word + sub) * width;
      for (int v = 0; v < count; ++v) {
        const ColumnJob& j = jobs[v];
        const std::int32_t bits = std::int32_t((j.rows[word] >> sub) & kSubMask);
        if (bits == 0) continue;
        const RowBits reached = (RowBits{} + bits) & lane_bit;
        for (int i = 0; i < images; ++i) {
          const float* lanes = band[i] + block;
          Rows even[kQuad] = {}, odd[kQuad] = {};
          std::size_t k = 0;
          for (; k + 2 <= j.n; k += 2) {
            dot_quad(even, lanes + std::size_t(j.first[k]) * kSubRows, j.w + kQuad * k);
            dot_quad(odd, lanes + std::size_t(j.first[k + 1]) * kSubRows, j.w + kQuad * (k + 1));
          }
          if (k < j.n) dot_quad(even, lanes + std::size_t(j.first[k]) * kSubRows, j.w + kQuad * k);
          const Rows lane0 = even[0] + odd[0], lane1 = even[1] + odd[1];
          const Rows lane2 = even[2] + odd[2], lane3 = even[3] + odd[3];
          const Rows sum = (lane0 + lane1) + (lane2 + lane3);
          const Rows kept = reached != 0 ? sum : Rows{};
          __builtin_memcpy(j.sums[std::size_t(i)] + 64 * word + sub, &kept, sizeof kept);
        }
      }
    }
  }
}

// The eq 13 normalisers' first stage: out[x] = Σ_col Ax_x(col) row(col) for every voxel x of a
// slice (its quads [start[x], start[x + 1])), for two rows at once (row_b null: one row).
__attribute__((target("default"))) void dot_slice_rows(const float* row_a, const float* row_b, const std::size_t* start,
                                                       const int* first, const float* w, int nx, double* out_a,
                                                       double* out_b) {
  for (int x = 0; x < nx; ++x) {
    const std::size_t q0 = start[x], n = start[x + 1] - q0;
    out_a[x] = dot_quads_base(row_a, first + q0, w + kQuad * q0, n);
    if (row_b) out_b[x] = dot_quads_base(row_b, first + q0, w + kQuad * q0, n);
  }
}
__attribute__((target("avx2"))) void dot_slice_rows(const float* row_a, const float* row_b, const std::size_t* start,
                                                    const int* first, const float* w, int nx, double* out_a,
                                                    double* out_b) {
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

// image[i] *= white[i] over a band, 4 pixels per vector (-O2 leaves the plain loop scalar).
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

// Runs f(item) for every item on the arena's threads, each thread taking the next item of the
// list when it is free. With the costliest items first, a pass ends on short ones instead of
// leaving a core idle while the other finishes a long last band or strip. Which thread runs an
// item does not change any sum.
template <typename F>
void run_costliest_first(const std::vector<int>& items, F&& f) {
  std::atomic<std::size_t> next{0};
  const int workers = std::max(1, std::min(tbb::this_task_arena::max_concurrency(), int(items.size())));
  tbb::parallel_for(0, workers, [&](int) {
    for (std::size_t i = next++; i < items.size(); i = next++) f(items[i]);
  }, tbb::simple_partitioner());
}

}  // namespace

ImageF geometric_white_image(const optics::CameraModel& camera, const optics::MicrolensArray& lenses) {
  const optics::SensorSpec& s = camera.sensor();
  ImageF white(s.width_px, s.height_px, 0.f);
  const double radius_px = 0.5 * camera.microlens_image_diameter_px();
  const double s_i = camera.image_distance_mm();
  const double f_l = camera.microlens().focal_length_mm;
  constexpr int kSub = 8;  // sub-samples per pixel axis on the disk edge
  // Each lens paints its own disk; disks do not overlap (eq 7 is checked by CameraModel), but
  // neighbouring disks may touch a shared edge pixel. So the work is shared out by pixel rows,
  // each row painted by the lenses that reach it in lens order: no two threads write one pixel
  // (sharing out by lens let two lenses update a shared edge pixel at once and lose one update,
  // about one run in 100 on the small camera).
  struct Spot {
    double cx, cy;
    int x0, x1;
  };
  std::vector<Spot> spots(lenses.centres_mm.size());
  std::vector<std::uint32_t> row_start(std::size_t(s.height_px) + 1, 0);
  std::vector<std::array<int, 2>> rows(spots.size());
  for (std::size_t lens = 0; lens < spots.size(); ++lens) {
    Spot& p = spots[lens];
    p.cx = optics::sensor_mm_to_column(s, optics::lens_centre_to_spot_mm(lenses.centres_mm[lens][0], s_i, f_l));
    p.cy = optics::sensor_mm_to_row(s, optics::lens_centre_to_spot_mm(lenses.centres_mm[lens][1], s_i, f_l));
    p.x0 = std::max(0, int(std::floor(p.cx - radius_px - 1)));
    p.x1 = std::min(s.width_px - 1, int(std::ceil(p.cx + radius_px + 1)));
    rows[lens] = {std::max(0, int(std::floor(p.cy - radius_px - 1))), std::min(s.height_px - 1, int(std::ceil(p.cy + radius_px + 1)))};
    for (int y = rows[lens][0]; y <= rows[lens][1]; ++y) ++row_start[std::size_t(y) + 1];
  }
  for (std::size_t y = 0; y < std::size_t(s.height_px); ++y) row_start[y + 1] += row_start[y];
  std::vector<std::uint32_t> row_lenses(row_start.back());
  std::vector<std::uint32_t> fill(row_start.begin(), row_start.end() - 1);
  for (std::size_t lens = 0; lens < spots.size(); ++lens) {
    for (int y = rows[lens][0]; y <= rows[lens][1]; ++y) row_lenses[fill[std::size_t(y)]++] = std::uint32_t(lens);
  }
  tbb::parallel_for(0, s.height_px, [&](int y) {
    for (std::uint32_t k = row_start[std::size_t(y)]; k < row_start[std::size_t(y) + 1]; ++k) {
      const Spot& p = spots[row_lenses[k]];
      for (int x = p.x0; x <= p.x1; ++x) {
        const double d = std::hypot(x - p.cx, y - p.cy);
        double fraction;
        if (d <= radius_px - 0.75) {
          fraction = 1.0;
        } else if (d >= radius_px + 0.75) {
          continue;
        } else {
          int inside = 0;
          for (int j = 0; j < kSub; ++j) {
            for (int i = 0; i < kSub; ++i) {
              const double px = x - 0.5 + (i + 0.5) / kSub - p.cx;
              const double py = y - 0.5 + (j + 0.5) / kSub - p.cy;
              inside += px * px + py * py <= radius_px * radius_px;
            }
          }
          fraction = double(inside) / (kSub * kSub);
        }
        float& w = white.at(x, y);
        w = std::min(1.f, w + float(fraction));
      }
    }
  });
  return white;
}

SeparableLattice separable_lattice(const optics::MicrolensArray& lenses) {
  const optics::Lattice& lat = lenses.lattice;
  if (lenses.centres_mm.size() != std::size_t(lat.count()))
    throw InputError("microlens array: " + std::to_string(lenses.centres_mm.size()) + " centres for " +
                     std::to_string(lat.count()) + " lenses");
  SeparableLattice out;
  // Separability: one x per lens column and one y per lens row (their means). A measured array
  // may scatter about them by a fraction of a pixel; a rotated or warped one cannot be separated.
  out.lens_x.assign(std::size_t(lat.count_x), 0.0);
  out.lens_y.assign(std::size_t(lat.count_y), 0.0);
  // Means as the first lens plus the mean departure from it, so an exact lattice stays exact.
  for (int j = 0; j < lat.count_y; ++j) {
    for (int i = 0; i < lat.count_x; ++i) {
      out.lens_x[std::size_t(i)] += (lenses.centre(i, j)[0] - lenses.centre(i, 0)[0]) / lat.count_y;
      out.lens_y[std::size_t(j)] += (lenses.centre(i, j)[1] - lenses.centre(0, j)[1]) / lat.count_x;
    }
  }
  for (int i = 0; i < lat.count_x; ++i) out.lens_x[std::size_t(i)] += lenses.centre(i, 0)[0];
  for (int j = 0; j < lat.count_y; ++j) out.lens_y[std::size_t(j)] += lenses.centre(0, j)[1];
  for (int j = 0; j < lat.count_y; ++j) {
    for (int i = 0; i < lat.count_x; ++i) {
      const double dev = std::max(std::abs(lenses.centre(i, j)[0] - out.lens_x[std::size_t(i)]),
                                  std::abs(lenses.centre(i, j)[1] - out.lens_y[std::size_t(j)]));
      out.max_departure_mm = std::max(out.max_departure_mm, dev);
    }
  }
  return out;
}

WeightingOperator::WeightingOperator(const optics::CameraModel& camera,
                                     const optics::MicrolensArray& lenses, const Grid3& grid,
                                     ImageF white, double angular_sampling)
    : grid_(grid),
      width_(camera.sensor().width_px),
      height_(camera.sensor().height_px),
      sensor_(camera.sensor()),
      white_(std::move(white)) {
  if (white_.width != width_ || white_.height != height_) {
    throw InputError("white image: " + std::to_string(white_.width) + " x " + std::to_string(white_.height) +
                     " px, the sensor is " + std::to_string(width_) + " x " + std::to_string(height_));
  }
  if (width_ < kQuad) throw InputError("sensor: the reconstruction needs at least 4 pixels per row");
  if (!(angular_sampling > 0 && angular_sampling <= 8)) {
    throw InputError("angular_sampling: must be in (0, 8], got " + std::to_string(angular_sampling));
  }
  for (int a = 0; a < 3; ++a) {
    if (grid_.shape[a] <= 0 || !(grid_.spacing_mm[a] > 0)) {
      throw InputError("volume grid: every axis needs at least one voxel and a positive spacing");
    }
  }
  const optics::Lattice& lat = lenses.lattice;
  if (lat.layout != optics::LensletLayout::rect) {
    throw InputError("microlens array: the reconstruction needs a rectangular lattice (hex arrays are "
                     "not supported yet)");
  }
  if (lat.count_x < 2 || lat.count_y < 2 || lenses.centres_mm.size() != std::size_t(lat.count())) {
    throw InputError("microlens array: needs at least 2 x 2 lenses and one centre per lens");
  }
  geo_.s_o = camera.object_distance_mm();
  geo_.s_i = camera.image_distance_mm();
  geo_.f_main = camera.main_lens().focal_length_mm;
  geo_.f_lens = camera.microlens().focal_length_mm;
  geo_.aperture = camera.aperture_diameter_mm();
  geo_.pixel_pitch = camera.sensor().pixel_pitch_mm;
  geo_.nominal_samples = std::max(2, int(std::ceil(camera.microlens_image_diameter_px() - 1e-9)));
  geo_.angular_sampling = angular_sampling;
  SeparableLattice sep = separable_lattice(lenses);
  geo_.lens_x = std::move(sep.lens_x);
  geo_.lens_y = std::move(sep.lens_y);
  geo_.max_centre_deviation_mm = sep.max_departure_mm;
  if (!sep.separable(geo_.pixel_pitch)) {
    throw InputError("microlens array: lens centres leave their lattice columns/rows by up to " +
                     std::to_string(geo_.max_centre_deviation_mm / geo_.pixel_pitch) +
                     " px (rotated or warped array); the separable weights allow " +
                     std::to_string(kSeparableTolerancePx) + " px");
  }
  geo_.min_pitch = 1e300;
  for (std::size_t i = 1; i < geo_.lens_x.size(); ++i) geo_.min_pitch = std::min(geo_.min_pitch, geo_.lens_x[i] - geo_.lens_x[i - 1]);
  for (std::size_t j = 1; j < geo_.lens_y.size(); ++j) geo_.min_pitch = std::min(geo_.min_pitch, geo_.lens_y[j] - geo_.lens_y[j - 1]);
  if (!(geo_.min_pitch > 0)) throw InputError("microlens array: centres must increase along rows and columns");

  const int nx = grid_.shape[0], ny = grid_.shape[1], nz = grid_.shape[2];
  slices_.resize(std::size_t(nz));
  for (int z = 0; z < nz; ++z) slice_optics(grid_.coordinate_mm(2, z));  // validates every depth

  auto column_of = [this](double mm) { return optics::sensor_mm_to_column(sensor_, mm); };
  auto row_of = [this](double mm) { return optics::sensor_mm_to_row(sensor_, mm); };
  tbb::parallel_for(0, nz, [&](int z) {
    SliceTables& t = slices_[std::size_t(z)];
    t.z_mm = grid_.coordinate_mm(2, z);
    const SliceOptics o = slice_optics(t.z_mm);
    t.alpha = o.alpha;
    t.magnification = o.magnification;
    t.samples = o.samples;
    std::vector<double> scratch(std::size_t(std::max(width_, height_)), 0.0);
    auto build = [&](int count, int axis, const std::vector<double>& centres, int pixels, auto pixel_of,
                     std::vector<WeightRun>& runs, std::vector<Segment>& segments, std::vector<float>& table) {
      runs.resize(std::size_t(count));
      for (int v = 0; v < count; ++v) {
        const double prime = o.magnification * grid_.coordinate_mm(axis, v);
        int lo = pixels, hi = -1;
        for (int k = 0; k < o.samples; ++k) {
          int pix[4];
          double w[4];
          const int n = ray_coefficients(geo_, centres, o.alpha, prime, sample_position(geo_.aperture, o.samples, k),
                                         pixels, pixel_of, pix, w);
          for (int h = 0; h < n; ++h) {
            scratch[std::size_t(pix[h])] += w[h];
            lo = std::min(lo, pix[h]);
            hi = std::max(hi, pix[h]);
          }
        }
        // Away from focus a voxel reaches a few pixels behind each of many lenses: keep only the
        // stretches with weight (gaps of up to kGap zeros are cheaper to carry than to split).
        constexpr int kGap = 2;
        WeightRun& run = runs[std::size_t(v)];
        run.first = lo;
        run.last = hi;
        run.segment_begin = segments.size();
        for (int p = lo; p <= hi;) {
          if (scratch[std::size_t(p)] == 0.0) {
            ++p;
            continue;
          }
          int end = p;  // last pixel with weight in this stretch
          for (int q = p + 1; q <= hi && q <= end + kGap + 1; ++q) {
            if (scratch[std::size_t(q)] != 0.0) end = q;
          }
          segments.push_back(Segment{p, end - p + 1, table.size()});
          for (int q = p; q <= end; ++q) table.push_back(float(scratch[std::size_t(q)]));
          p = end + 1;
        }
        run.segment_end = segments.size();
        for (int p = lo; p <= hi; ++p) scratch[std::size_t(p)] = 0.0;
      }
    };
    build(nx, 0, geo_.lens_x, width_, column_of, t.x_runs, t.x_segments, t.x_table);
    build(ny, 1, geo_.lens_y, height_, row_of, t.y_runs, t.y_segments, t.y_table);
    build_quads(t.x_runs, t.x_segments, t.x_table, width_, t.x_quad_start, t.x_quad_first, t.x_quad_weights);
    build_quads(t.y_runs, t.y_segments, t.y_table, 0, t.y_quad_start, t.y_quad_first, t.y_quad_weights);
  });

  // Eq 13's denominators n_j = Σ_rows Ay Σ_cols Ax white, in two separable stages per slice.
  normaliser_.assign(grid_.count(), 0.f);
  tbb::parallel_for(0, nz, [&](int z) {
    const SliceTables& t = slices_[std::size_t(z)];
    int r_lo = height_, r_hi = -1;
    for (const WeightRun& r : t.y_runs) {
      if (r.last < r.first) continue;
      r_lo = std::min(r_lo, r.first);
      r_hi = std::max(r_hi, r.last);
    }
    if (r_hi < r_lo) return;
    const std::size_t rows = std::size_t(r_hi - r_lo + 1);
    std::vector<double> g(rows * std::size_t(nx), 0.0);  // [row][x]
    for (std::size_t r = 0; r < rows; r += 2) {
      const float* wrow = white_.pixels.data() + (std::size_t(r_lo) + r) * std::size_t(width_);
      dot_slice_rows(wrow, r + 1 < rows ? wrow + width_ : nullptr, t.x_quad_start.data(), t.x_quad_first.data(),
                     t.x_quad_weights.data(), nx, g.data() + r * std::size_t(nx), g.data() + (r + 1) * std::size_t(nx));
    }
    for (int y = 0; y < ny; ++y) {
      const AxisWeights ay = y_weights(z, y);
      for (int x = 0; x < nx; ++x) {
        double s = 0;
        for (const Segment& seg : ay.segments) {
          for (int r = 0; r < seg.length; ++r) {
            s += double(ay.table[seg.offset + std::size_t(r)]) *
                 g[std::size_t(seg.first + r - r_lo) * std::size_t(nx) + std::size_t(x)];
          }
        }
        normaliser_[grid_.index(x, y, z)] = float(s);
      }
    }
  });
}

SliceOptics WeightingOperator::slice_optics(double z_mm) const {
  // Eq 10 with s'_o = s_o + z_o (DESIGN.md: the printed s_i + z_o holds only at M = -1).
  const double so = geo_.s_o + z_mm;
  if (!(so > geo_.f_main * (1 + 1e-9))) {
    throw InputError("volume grid: depth z = " + std::to_string(z_mm) +
                     " mm lies at or inside the main lens's focal length; no real image forms there");
  }
  const double si = geo_.f_main * so / (so - geo_.f_main);
  SliceOptics o;
  o.alpha = si / geo_.s_i;
  o.magnification = -si / so;
  // Sec 5.2: enough rays that their spacing on the microlens plane stays under one microlens,
  // and never fewer than the nominal angular sampling (pixels across a microlens image); then
  // scaled by the operator's angular_sampling (a time-against-accuracy knob), at least 2.
  const double spread = geo_.aperture * std::abs(1.0 - 1.0 / o.alpha);
  const int sec52 = std::max(geo_.nominal_samples, int(std::floor(spread / geo_.min_pitch)) + 1);
  o.samples = std::max(2, int(std::ceil(geo_.angular_sampling * sec52 - 1e-9)));
  return o;
}

namespace {
AxisWeights axis_weights(const WeightRun& r, const std::vector<Segment>& segments, const std::vector<float>& table) {
  AxisWeights w;
  w.segments = {segments.data() + r.segment_begin, r.segment_end - r.segment_begin};
  w.table = table.data();
  w.first = r.first;
  w.last = r.last;
  return w;
}
}  // namespace

float AxisWeights::at(int p) const {
  for (const Segment& s : segments) {
    if (p >= s.first && p < s.first + s.length) return table[s.offset + std::size_t(p - s.first)];
  }
  return 0.f;
}

AxisWeights WeightingOperator::x_weights(int z, int x) const {
  const SliceTables& t = slices_[std::size_t(z)];
  return axis_weights(t.x_runs[std::size_t(x)], t.x_segments, t.x_table);
}
AxisWeights WeightingOperator::y_weights(int z, int y) const {
  const SliceTables& t = slices_[std::size_t(z)];
  return axis_weights(t.y_runs[std::size_t(y)], t.y_segments, t.y_table);
}

void WeightingOperator::project(std::span<const float> volume, std::span<float> image) const {
  if (volume.size() != grid_.count() || image.size() != pixel_count()) {
    throw InputError("project: volume or image size does not match the operator");
  }
  ActiveSet::all(*this).project(*this, volume, image);
}

void WeightingOperator::back_project(std::span<const float> image, std::span<float> volume) const {
  if (volume.size() != grid_.count() || image.size() != pixel_count()) {
    throw InputError("back_project: volume or image size does not match the operator");
  }
  ActiveSet::all(*this).back_project(*this, image, volume);
}

// ---------------------------------------------------------------------------------------------

ActiveSet::ActiveSet(const WeightingOperator& op, std::vector<std::uint32_t> voxels)
    : voxels_(std::move(voxels)) {
  const Grid3& g = op.grid();
  const std::uint32_t nx = std::uint32_t(g.shape[0]), nz = std::uint32_t(g.shape[2]);
  const std::uint32_t nxy = nx * std::uint32_t(g.shape[1]);
  // 16 voxel x per strip (~1.6 mm on the paper's camera), fewer on small grids so that there are
  // at least 8 strips to share out; fixed by the grid, so the sums' order is too.
  strip_x_ = std::clamp(int(nx) / 8, 1, 16);
  strips_ = (int(nx) + strip_x_ - 1) / strip_x_;
  const std::uint32_t sx = std::uint32_t(strip_x_);
  // A voxel column's place in the visiting order: strip, depth, x within the strip.
  auto key_of = [&](std::uint32_t x, std::uint32_t z) { return (std::size_t(x / sx) * nz + z) * sx + x % sx; };
  if (std::adjacent_find(voxels_.begin(), voxels_.end(), std::greater_equal<>()) != voxels_.end() ||
      (!voxels_.empty() && voxels_.back() >= g.count())) {
    throw InputError("active set: voxel indices must be distinct, increasing and inside the grid");
  }
  // Group by voxel column in that order with a counting sort, slice by slice in parallel (the
  // voxels are sorted, so each slice is one stretch of them): y stays increasing within a
  // column. A voxel that sees no pixel (n = 0) takes no part; its value is 0.
  std::vector<std::size_t> slice_begin(std::size_t(nz) + 1);
  for (std::uint32_t z = 0; z <= nz; ++z) {
    slice_begin[z] = std::size_t(std::lower_bound(voxels_.begin(), voxels_.end(), std::uint64_t(z) * nxy) - voxels_.begin());
  }
  std::vector<std::uint32_t> column_count(std::size_t(nz) * nx, 0);  // [z][x]
  tbb::parallel_for(std::uint32_t(0), nz, [&](std::uint32_t z) {
    for (std::size_t m = slice_begin[z]; m < slice_begin[z + 1]; ++m) {
      if (op.normaliser(voxels_[m]) > 0.f) ++column_count[std::size_t(z) * nx + voxels_[m] % nx];
    }
  });
  std::vector<std::uint32_t> start(std::size_t(strips_) * nz * sx + 1, 0);
  for (std::uint32_t z = 0; z < nz; ++z) {
    for (std::uint32_t x = 0; x < nx; ++x) start[key_of(x, z) + 1] = column_count[std::size_t(z) * nx + x];
  }
  for (std::size_t c = 1; c < start.size(); ++c) start[c] += start[c - 1];
  order_.resize(start.back());
  order_normaliser_.resize(start.back());
  BigBuffer<int> order_y(start.back());  // written in full below
  tbb::parallel_for(std::uint32_t(0), nz, [&](std::uint32_t z) {
    std::uint32_t* fill = column_count.data() + std::size_t(z) * nx;  // now each column's next place
    for (std::uint32_t x = 0; x < nx; ++x) fill[x] = start[key_of(x, z)];
    for (std::size_t m = slice_begin[z]; m < slice_begin[z + 1]; ++m) {
      const std::uint32_t v = voxels_[m];
      const float n = op.normaliser(v);
      if (!(n > 0.f)) continue;
      const std::uint32_t p = fill[v % nx]++;
      order_[p] = std::uint32_t(m);
      order_y[p] = int((v % nxy) / nx);
      order_normaliser_[p] = n;
    }
  });
  strip_columns_.assign(std::size_t(strips_) + 1, 0);
  for (std::size_t key = 0; key + 1 < start.size(); ++key) {
    if (start[key + 1] == start[key]) continue;
    const std::size_t strip = key / (std::size_t(nz) * sx);
    columns_.push_back(Column{int((key / sx) % nz), int(strip * sx + key % sx), start[key], start[key + 1]});
    strip_columns_[strip + 1] = std::uint32_t(columns_.size());
  }
  for (int s = 1; s <= strips_; ++s) strip_columns_[std::size_t(s)] = std::max(strip_columns_[std::size_t(s)], strip_columns_[std::size_t(s) - 1]);
  // Per column, band by band, the voxels whose rows reach the band and their segments there:
  // counted, then written, both in parallel over columns.
  const int height = op.image_height();
  bands_ = (height + kBandRows - 1) / kBandRows;
  std::vector<int> first_band(columns_.size()), last_band(columns_.size());
  // Calls entry(b, p, first quad, count) for each voxel p of column c whose y quads reach band b
  // (a quad may reach two bands: it is in both), for the column's bands only: voxel by voxel in
  // y order, each voxel's bands in order, so the entries of one band keep y order.
  auto walk = [&](std::size_t c, auto&& entry) {
    const Column& col = columns_[c];
    const SliceTables& t = op.slice(col.z);
    for (std::uint32_t p = col.begin; p < col.end; ++p) {
      const std::size_t q0 = t.y_quad_start[std::size_t(order_y[p])], q1 = t.y_quad_start[std::size_t(order_y[p]) + 1];
      if (q0 == q1) continue;
      const int b0 = std::max(first_band[c], t.y_quad_first[q0] / kBandRows);
      const int b1 = std::min(last_band[c], (t.y_quad_first[q1 - 1] + kQuad - 1) / kBandRows);
      std::size_t k = q0;
      for (int b = b0; b <= b1; ++b) {
        const int r0 = b * kBandRows, r1 = std::min(height, r0 + kBandRows);
        while (k < q1 && t.y_quad_first[k] + kQuad <= r0) ++k;
        std::size_t e = k;
        while (e < q1 && t.y_quad_first[e] < r1) ++e;
        if (e > k) entry(b, p, k, e - k);
      }
    }
  };
  // Entries per (column, band): block_offset[c] + band - first_band[c].
  std::vector<std::size_t> block_offset(columns_.size() + 1, 0);
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, columns_.size(), 64),
                    [&](const tbb::blocked_range<std::size_t>& range) {
    for (std::size_t c = range.begin(); c != range.end(); ++c) {
      const Column& col = columns_[c];
      const SliceTables& t = op.slice(col.z);
      first_band[c] = height;
      last_band[c] = -1;
      for (std::uint32_t p = col.begin; p < col.end; ++p) {
        const WeightRun& run = t.y_runs[std::size_t(order_y[p])];
        first_band[c] = std::min(first_band[c], run.first / kBandRows);
        last_band[c] = std::max(last_band[c], run.last / kBandRows);
      }
      block_offset[c + 1] = std::size_t(last_band[c] - first_band[c] + 1);
    }
  });
  for (std::size_t c = 0; c < columns_.size(); ++c) block_offset[c + 1] += block_offset[c];
  std::vector<std::uint32_t> block_entries(block_offset.back(), 0);
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, columns_.size(), 64),
                    [&](const tbb::blocked_range<std::size_t>& range) {
    for (std::size_t c = range.begin(); c != range.end(); ++c) {
      walk(c, [&](int b, std::uint32_t, std::size_t, std::size_t) {
        ++block_entries[block_offset[c] + std::size_t(b - first_band[c])];
      });
    }
  });
  // The visits in the order the kernels read them: band by band, then strip by strip, depth by
  // depth, x by x (columns_'s order), each with its entries; counted, then laid out.
  auto for_each_visit = [&](auto&& f) {
    for (int b = 0; b < bands_; ++b) {
      for (int s = 0; s < strips_; ++s) {
        for (std::uint32_t c = strip_columns_[std::size_t(s)]; c < strip_columns_[std::size_t(s) + 1]; ++c) {
          if (b < first_band[c] || b > last_band[c]) continue;
          const std::size_t block = block_offset[c] + std::size_t(b - first_band[c]);
          if (block_entries[block] > 0) f(b, s, c, block);
        }
      }
    }
  };
  visit_start_.assign(std::size_t(bands_) * std::size_t(strips_) + 1, 0);
  for_each_visit([&](int b, int s, std::uint32_t, std::size_t) { ++visit_start_[std::size_t(b) * std::size_t(strips_) + std::size_t(s) + 1]; });
  for (std::size_t i = 1; i < visit_start_.size(); ++i) visit_start_[i] += visit_start_[i - 1];
  visits_.resize(visit_start_.back());
  std::vector<std::size_t> block_visit(block_offset.back());
  std::size_t next_visit = 0, next_entry = 0;
  for_each_visit([&](int, int, std::uint32_t c, std::size_t block) {
    if (next_entry + block_entries[block] > std::numeric_limits<std::uint32_t>::max()) {
      throw InputError("reconstruction: more than 2^32 voxel-band entries; use a coarser volume grid");
    }
    Visit& v = visits_[next_visit];
    v.column = c;
    v.entry_begin = std::uint32_t(next_entry);
    next_entry += block_entries[block];
    v.entry_end = std::uint32_t(next_entry);
    v.rows = {};
    block_visit[block] = next_visit++;
  });
  entries_.resize(next_entry);
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, columns_.size(), 64),
                    [&](const tbb::blocked_range<std::size_t>& range) {
    for (std::size_t c = range.begin(); c != range.end(); ++c) {
      const SliceTables& t = op.slice(columns_[c].z);
      walk(c, [&](int b, std::uint32_t p, std::size_t k, std::size_t n) {
        const std::size_t block = block_offset[c] + std::size_t(b - first_band[c]);
        Visit& v = visits_[block_visit[block]];
        entries_[v.entry_end - block_entries[block]--] = BandEntry{p, std::uint32_t(k), std::uint32_t(n)};  // in y order
        const int r0 = b * kBandRows, r1 = std::min(height, r0 + kBandRows);
        // The rows with weight, a quad's lanes at a time: bit j for row first + j, without the
        // lanes in the neighbouring bands.
        for (std::size_t q = k; q < k + n; ++q) {
          const float* w = t.y_quad_weights.data() + kQuad * q;
          // Bit j: lane j's weight is not 0 (one SSE compare, not four scalar ones).
          std::uint64_t lanes = std::uint64_t(_mm_movemask_ps(_mm_cmpneq_ps(_mm_loadu_ps(w), _mm_setzero_ps())));
          int at = t.y_quad_first[q] - r0;
          if (at < 0) {
            lanes >>= -at;
            at = 0;
          }
          if (r1 - r0 - at < kQuad) lanes &= (std::uint64_t(1) << (r1 - r0 - at)) - 1;
          v.rows[std::size_t(at >> 6)] |= lanes << (at & 63);
          if ((at & 63) > 64 - kQuad && (at >> 6) + 1 < kRowWords) v.rows[std::size_t(at >> 6) + 1] |= lanes >> (64 - (at & 63));
        }
      });
    }
  });
  // The work of each band and strip, estimated as the kernels' quad operations (rows reached
  // times x quads) plus a share per entry, to hand out the costliest first.
  std::vector<double> band_cost(std::size_t(bands_), 0.0), strip_cost(std::size_t(strips_), 0.0);
  for (int b = 0; b < bands_; ++b) {
    for (int s = 0; s < strips_; ++s) {
      const std::size_t slot = std::size_t(b) * std::size_t(strips_) + std::size_t(s);
      for (std::size_t i = visit_start_[slot]; i < visit_start_[slot + 1]; ++i) {
        const Visit& v = visits_[i];
        const Column& col = columns_[v.column];
        const SliceTables& t = op.slice(col.z);
        int rows = 0;
        for (std::uint64_t word : v.rows) rows += std::popcount(word);
        const double cost = double(rows) * double(t.x_quad_start[std::size_t(col.x) + 1] - t.x_quad_start[std::size_t(col.x)] + 2) +
                            8.0 * double(v.entry_end - v.entry_begin);
        band_cost[std::size_t(b)] += cost;
        strip_cost[std::size_t(s)] += cost;
      }
    }
  }
  auto costliest_first = [](const std::vector<double>& cost) {
    std::vector<int> order(cost.size());
    std::iota(order.begin(), order.end(), 0);
    std::stable_sort(order.begin(), order.end(), [&](int a, int b) { return cost[std::size_t(a)] > cost[std::size_t(b)]; });
    return order;
  };
  band_order_ = costliest_first(band_cost);
  strip_order_ = costliest_first(strip_cost);
}

ActiveSet ActiveSet::all(const WeightingOperator& op) {
  std::vector<std::uint32_t> v(op.grid().count());
  for (std::size_t i = 0; i < v.size(); ++i) v[i] = std::uint32_t(i);
  return ActiveSet(op, std::move(v));
}
void ActiveSet::project(const WeightingOperator& op, std::span<const float> values, std::span<float> image,
                        Workspace* workspace, const BandDone& band_done) const {
  const std::size_t width = std::size_t(op.image_width());
  const int height = op.image_height();
  Workspace local;
  Workspace& ws = workspace ? *workspace : local;
  // E / n once per voxel, in visiting order.
  auto& scaled = ws.scaled;
  scaled.resize(order_.size());
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, order_.size(), 1 << 14),
                    [&](const tbb::blocked_range<std::size_t>& r) {
    for (std::size_t p = r.begin(); p != r.end(); ++p) scaled[p] = values[order_[p]] / order_normaliser_[p];
  });
  const std::size_t band_size = std::size_t(kBandRows) * width;
  ws.band_lanes.resize(std::size_t(tbb::this_task_arena::max_concurrency()) * band_size);
  // Each band owns its sensor rows and adds its columns in a fixed order: no atomics, and the
  // same sums whatever the thread count.
  run_costliest_first(band_order_, [&](int b) {
    const int r0 = b * kBandRows, r1 = std::min(height, r0 + kBandRows);
    // The band in row lanes, this thread's own, copied into the image when finished.
    float* lanes = ws.band_lanes.data() + std::size_t(tbb::this_task_arena::current_thread_index()) * band_size;
    std::fill_n(lanes, band_size, 0.f);
    // G(row) of kChunk consecutive visits over the band's rows, each with kQuad rows of margin on
    // either side for the lanes of quads that straddle the band's edges (those belong to the
    // neighbouring band). Zero between uses: stage 2 resets the rows it adds, then the margins.
    std::array<std::array<float, kQuad + kBandRows + kQuad>, kChunk> padded_sums;
    for (auto& p : padded_sums) p.fill(0.f);
    const std::size_t v_begin = visit_start_[std::size_t(b) * std::size_t(strips_)];
    const std::size_t v_end = visit_start_[std::size_t(b + 1) * std::size_t(strips_)];
    for (std::size_t c0 = v_begin; c0 < v_end; c0 += kChunk) {
      const std::size_t c1 = std::min(v_end, c0 + kChunk);
      for (std::size_t v = c0; v < c1; ++v) {
        const Visit& visit = visits_[v];
        const SliceTables& t = op.slice(columns_[visit.column].z);
        float* const column_sum = padded_sums[v - c0].data() + kQuad;
        // Stage 1: G(row) = Σ_y Ay_y(row) E_y / n_y over the column's voxels that reach the band,
        // one quad of rows at a time; a quad's padded lanes add s · 0 = +0, which leaves every sum
        // as it was, so each row gets the same float additions in the same order as row by row.
        for (std::size_t k = visit.entry_begin; k < visit.entry_end; ++k) {
          const BandEntry& entry = entries_[k];
          const float s = scaled[entry.position];
          if (s == 0.f) continue;
          const int* first = t.y_quad_first.data() + entry.quad_begin;
          const float* w = t.y_quad_weights.data() + kQuad * std::size_t(entry.quad_begin);
          for (std::uint32_t q = 0; q < entry.quad_count; ++q) {
            float* g = column_sum + (first[q] - r0);
            Lanes4 sum, wq;
            __builtin_memcpy(&sum, g, sizeof sum);
            __builtin_memcpy(&wq, w + kQuad * q, sizeof wq);
            sum += s * wq;
            __builtin_memcpy(g, &sum, sizeof sum);
          }
        }
      }
      // Stage 2: lanes(row, ·) += G(row) Ax over each 16-row block the column reaches (resets
      // G there), one block at a time for all the chunk's visits, so the pixels they share stay
      // in L1. Every pixel still gets its visits' additions in visiting order.
      std::array<ColumnJob, kChunk> jobs;
      for (std::size_t v = c0; v < c1; ++v) {
        const Column& col = columns_[visits_[v].column];
        jobs[v - c0] = x_job(op.slice(col.z), col.x, visits_[v].rows.data());
        jobs[v - c0].sums[0] = padded_sums[v - c0].data() + kQuad;
      }
      add_columns(lanes, width, kRowWords, jobs.data(), int(c1 - c0));
      for (std::size_t v = c0; v < c1; ++v) {
        std::fill_n(padded_sums[v - c0].begin(), kQuad, 0.f);
        std::fill_n(padded_sums[v - c0].end() - kQuad, kQuad, 0.f);
      }
    }
    lanes_to_rows(lanes, width, r1 - r0, image.data() + std::size_t(r0) * width);
    const float* white = op.white().pixels.data();
    white_band(image.data() + std::size_t(r0) * width, white + std::size_t(r0) * width, std::size_t(r1 - r0) * width);
    if (band_done) band_done(b, std::size_t(r0) * width, std::size_t(r1) * width);
  });
}

void ActiveSet::back_project(const WeightingOperator& op, std::span<const float> image,
                             std::span<float> values) const {
  std::vector<float> whitened(image.size());
  const float* white = op.white().pixels.data();
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, image.size(), 1 << 14),
                    [&](const tbb::blocked_range<std::size_t>& r) {
    for (std::size_t i = r.begin(); i != r.end(); ++i) whitened[i] = image[i] * white[i];
  });
  back_project_whitened(op, whitened, values);
}

void ActiveSet::back_project_whitened(const WeightingOperator& op, std::span<const float> image,
                                      std::span<float> values, Workspace* workspace) const {
  Workspace local;
  back_project_images<1>(op, {image.data()}, {values.data()}, workspace ? *workspace : local);
}

void ActiveSet::back_project_whitened(const WeightingOperator& op, std::span<const float> whitened_a,
                                      std::span<float> values_a, std::span<const float> whitened_b,
                                      std::span<float> values_b, Workspace* workspace) const {
  Workspace local;
  back_project_images<2>(op, {whitened_a.data(), whitened_b.data()}, {values_a.data(), values_b.data()},
                         workspace ? *workspace : local);
}

template <std::size_t N>
void ActiveSet::back_project_images(const WeightingOperator& op, const std::array<const float*, N>& images,
                                    const std::array<float*, N>& values, Workspace& workspace) const {
  static_assert(N == 1 || N == 2, "ColumnJob holds the sums of at most two images");
  const std::size_t width = std::size_t(op.image_width());
  for (float* v : values) std::fill(v, v + voxels_.size(), 0.f);  // voxels that see no pixel
  // Per image and voxel in visiting order; each strip zeroes and sums its own range.
  auto& sums = workspace.sums;
  sums.resize(N * order_.size());
  // The images in row lanes, band by band in parallel: the last block's rows past the sensor are
  // 0; blocks wholly past it are left unwritten (no visit reaches them, so none is read).
  const int height = op.image_height();
  const std::size_t image_size = std::size_t(bands_) * std::size_t(kBandRows) * width;
  workspace.image_lanes.resize(N * image_size);
  tbb::parallel_for(0, int(N) * bands_, [&](int item) {
    const std::size_t i = std::size_t(item / bands_);
    const int r0 = (item % bands_) * kBandRows;
    rows_to_lanes(images[i] + std::size_t(r0) * width, width, std::min(height, r0 + kBandRows) - r0,
                  workspace.image_lanes.data() + i * image_size + std::size_t(r0) * width);
  });
  // Each strip owns its voxels (a contiguous range of order_), so their sums need no atomics,
  // and every voxel adds its bands in order whatever the thread count.
  run_costliest_first(strip_order_, [&](int strip) {
    const std::uint32_t c0 = strip_columns_[std::size_t(strip)], c1 = strip_columns_[std::size_t(strip) + 1];
    if (c0 == c1) return;
    const std::uint32_t p0 = columns_[c0].begin, p1 = columns_[c1 - 1].end;
    for (std::size_t i = 0; i < N; ++i) std::fill_n(sums.begin() + std::ptrdiff_t(i * order_.size() + p0), p1 - p0, 0.0);
    // B(row) of kChunk consecutive visits over the band's rows, with kQuad rows of margin on
    // either side, all 0 except the rows the column reaches: the lanes of y quads outside the
    // band, and their zero lanes on rows the column does not reach, then add 0 · 0 (a stale
    // value from another column would give 0 too if finite, but not if a row sum overflowed).
    std::array<std::array<std::array<float, kQuad + kBandRows + kQuad>, kChunk>, N> padded_sums;
    for (int b = 0; b < bands_; ++b) {
      const int r0 = b * kBandRows;
      const std::size_t slot = std::size_t(b) * std::size_t(strips_) + std::size_t(strip);
      for (std::size_t v0 = visit_start_[slot]; v0 < visit_start_[slot + 1]; v0 += kChunk) {
        const std::size_t v1 = std::min(visit_start_[slot + 1], v0 + kChunk);
        for (std::size_t i = 0; i < N; ++i) {
          for (std::size_t v = v0; v < v1; ++v) padded_sums[i][v - v0].fill(0.f);
        }
        // Stage 1: B(row) = Σ_col Ax(col) r(row, col) over each 16-row block the column reaches
        // (its unreached rows kept 0), one block at a time for all the chunk's visits, so the
        // pixels they share stay in L1.
        std::array<ColumnJob, kChunk> jobs;
        for (std::size_t v = v0; v < v1; ++v) {
          const Column& col = columns_[visits_[v].column];
          jobs[v - v0] = x_job(op.slice(col.z), col.x, visits_[v].rows.data());
          for (std::size_t i = 0; i < N; ++i) jobs[v - v0].sums[i] = padded_sums[i][v - v0].data() + kQuad;
        }
        std::array<const float*, N> bands;
        for (std::size_t i = 0; i < N; ++i) bands[i] = workspace.image_lanes.data() + i * image_size + std::size_t(r0) * width;
        dot_columns(bands.data(), int(N), width, kRowWords, jobs.data(), int(v1 - v0));
        // Stage 2: per voxel Σ_row Ay(row) B(row) over the band's rows, one quad of rows at a
        // time, lane after lane: the zero lanes add +0, so the sums are those row by row.
        for (std::size_t v = v0; v < v1; ++v) {
          const Visit& visit = visits_[v];
          const SliceTables& t = op.slice(columns_[visit.column].z);
          std::array<const float*, N> row_sum;
          for (std::size_t i = 0; i < N; ++i) row_sum[i] = padded_sums[i][v - v0].data() + kQuad;
          for (std::size_t k = visit.entry_begin; k < visit.entry_end; ++k) {
            const BandEntry& entry = entries_[k];
            const int* first = t.y_quad_first.data() + entry.quad_begin;
            const float* w = t.y_quad_weights.data() + kQuad * std::size_t(entry.quad_begin);
            std::array<double, N> s{};
            for (std::uint32_t q = 0; q < entry.quad_count; ++q) {
              Lanes4 wq;
              __builtin_memcpy(&wq, w + kQuad * q, sizeof wq);
              const Doubles4 wd = __builtin_convertvector(wq, Doubles4);
              for (std::size_t i = 0; i < N; ++i) {
                Lanes4 bq;
                __builtin_memcpy(&bq, row_sum[i] + (first[q] - r0), sizeof bq);
                // Products of floats are exact in double: only the order of the adds matters.
                const Doubles4 p = wd * __builtin_convertvector(bq, Doubles4);
                s[i] = (((s[i] + p[0]) + p[1]) + p[2]) + p[3];
              }
            }
            for (std::size_t i = 0; i < N; ++i) sums[i * order_.size() + entry.position] += s[i];
          }
        }
      }
    }
    for (std::size_t i = 0; i < N; ++i) {
      for (std::uint32_t p = p0; p < p1; ++p) {
        values[i][order_[p]] = float(sums[i * order_.size() + p] / order_normaliser_[p]);  // eq 13
      }
    }
  });
}

// ---------------------------------------------------------------------------------------------

void SparseMatrix::multiply(std::span<const float> x, std::span<float> y) const {
  for (std::size_t r = 0; r < rows; ++r) {
    double s = 0;
    for (std::size_t k = row_start[r]; k < row_start[r + 1]; ++k) s += double(values[k]) * x[col_index[k]];
    y[r] = float(s);
  }
}

void SparseMatrix::multiply_transpose(std::span<const float> y, std::span<float> x) const {
  std::vector<double> acc(cols, 0.0);
  for (std::size_t r = 0; r < rows; ++r) {
    for (std::size_t k = row_start[r]; k < row_start[r + 1]; ++k) acc[col_index[k]] += double(values[k]) * y[r];
  }
  for (std::size_t c = 0; c < cols; ++c) x[c] = float(acc[c]);
}

SparseMatrix build_explicit_matrix(const WeightingOperator& op) {
  const Grid3& g = op.grid();
  const WeightingOperator::Geometry& geo = op.geometry();
  const int width = op.image_width(), height = op.image_height();
  const optics::SensorSpec& sensor = op.sensor();
  auto column_of = [&](double mm) { return optics::sensor_mm_to_column(sensor, mm); };
  auto row_of = [&](double mm) { return optics::sensor_mm_to_row(sensor, mm); };

  // Columns of W (one per voxel), each a list of (pixel, weight).
  std::vector<std::vector<std::pair<std::uint32_t, float>>> columns(g.count());
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, g.count(), 16),
                    [&](const tbb::blocked_range<std::size_t>& range) {
    std::vector<std::pair<std::uint32_t, double>> entries;
    for (std::size_t j = range.begin(); j != range.end(); ++j) {
      const int x = int(j % std::size_t(g.shape[0]));
      const int y = int((j / std::size_t(g.shape[0])) % std::size_t(g.shape[1]));
      const int z = int(j / (std::size_t(g.shape[0]) * std::size_t(g.shape[1])));
      const SliceOptics o = op.slice_optics(g.coordinate_mm(2, z));
      const double xp = o.magnification * g.coordinate_mm(0, x);
      const double yp = o.magnification * g.coordinate_mm(1, y);
      entries.clear();
      // Literally sec 5.2: every ray of the plaid (u, v) grid through the voxel, its 4 lenses
      // and 4 pixels behind each (eq 12), times the white image (fig 15).
      for (int ku = 0; ku < o.samples; ++ku) {
        const double u = sample_position(geo.aperture, o.samples, ku);
        int cu[4];
        double wu[4];
        const int nu = ray_coefficients(geo, geo.lens_x, o.alpha, xp, u, width, column_of, cu, wu);
        for (int kv = 0; kv < o.samples; ++kv) {
          const double v = sample_position(geo.aperture, o.samples, kv);
          int rv[4];
          double wv[4];
          const int nv = ray_coefficients(geo, geo.lens_y, o.alpha, yp, v, height, row_of, rv, wv);
          for (int a = 0; a < nu; ++a) {
            for (int b = 0; b < nv; ++b) {
              const std::uint32_t pixel = std::uint32_t(rv[b]) * std::uint32_t(width) + std::uint32_t(cu[a]);
              const double w = wu[a] * wv[b] * op.white().pixels[pixel];
              if (w > 0) entries.emplace_back(pixel, w);
            }
          }
        }
      }
      std::sort(entries.begin(), entries.end(),
                [](const auto& p, const auto& q) { return p.first < q.first; });
      double total = 0;
      for (const auto& e : entries) total += e.second;
      auto& col = columns[j];
      for (std::size_t k = 0; k < entries.size();) {
        double s = 0;
        const std::uint32_t pixel = entries[k].first;
        for (; k < entries.size() && entries[k].first == pixel; ++k) s += entries[k].second;
        col.emplace_back(pixel, float(s / total));  // eq 13
      }
    }
  });

  SparseMatrix m;
  m.rows = op.pixel_count();
  m.cols = g.count();
  m.row_start.assign(m.rows + 1, 0);
  for (const auto& col : columns) {
    for (const auto& e : col) ++m.row_start[e.first + 1];
  }
  for (std::size_t r = 0; r < m.rows; ++r) m.row_start[r + 1] += m.row_start[r];
  m.col_index.resize(m.row_start.back());
  m.values.resize(m.row_start.back());
  std::vector<std::size_t> fill(m.row_start.begin(), m.row_start.end() - 1);
  for (std::size_t j = 0; j < columns.size(); ++j) {
    for (const auto& e : columns[j]) {
      const std::size_t k = fill[e.first]++;
      m.col_index[k] = std::uint32_t(j);
      m.values[k] = e.second;
    }
  }
  return m;
}

}  // namespace plenopiv::recon
