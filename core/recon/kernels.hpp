// The reconstruction's vector micro-kernels and their data layout (quads of 4 weights, row lanes
// of 16 sensor rows, chunks of visits), built for AVX-512, AVX2 and baseline x86-64 and chosen at
// run time. Internal to core/recon.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>

#include "core/recon/weights.hpp"

namespace plenopiv::recon::kernels {

// Pixels per quad: one SSE vector, and at least as long as most segments away from focus (2-4
// pixels behind each lens on the paper's camera beyond 5 mm from focus).
inline constexpr int kQuad = 4;
// The x stages take kChunk visits (voxel columns in one band) at a time and walk them one block
// of kSubRows sensor rows at a time, so that the pixels those visits share in those rows (a few
// KB) stay in L1 instead of being fetched again for every column (docs/recon.md, "Order and
// cache"). kSubRows is also the width of the row lanes (below): one AVX-512 register of floats.
inline constexpr int kChunk = 32;
inline constexpr int kSubRows = 16;
static_assert(64 % kSubRows == 0 && kSubRows <= 64);
// One block of kSubRows rows out of a 64-row word of reached rows (a visit's rows >> sub).
inline constexpr std::uint64_t kSubMask = ~std::uint64_t(0) >> (64 - kSubRows);

using Lanes4 = float __attribute__((vector_size(16)));
using Doubles4 = double __attribute__((vector_size(32)));

// One visit of a chunk as the x stages see it: its row sums over the band (G for the
// projection, B for the back-projection; pointing at the band's first row), the
// band's rows it reaches (one bit per row, `words` 64-bit words), and its column's x quads.
struct ColumnJob {
  float* sums;
  const std::uint64_t* rows;
  const int* first;
  const float* w;
  std::size_t n;
};
// The job of voxel column x of slice `t` reaching the band rows `rows`, its sums not yet set.
inline ColumnJob x_job(const SliceTables& t, int x, const std::uint64_t* rows) {
  const std::size_t q0 = t.x_quad_start[std::size_t(x)];
  const std::size_t q1 = t.x_quad_start[std::size_t(x) + 1];
  return ColumnJob{nullptr, rows, t.x_quad_first.data() + q0, t.x_quad_weights.data() + kQuad * q0, q1 - q0};
}

// One voxel of a visit in one band, as the y stages see it: its place in the pass's per-voxel
// arrays and its y quads that overlap the band (into its slice's y_quad_first / y_quad_weights).
// Packed into 8 bytes (a paper-scale active set holds millions): a slice has fewer than 2^24 y
// quads and a voxel row at most 255 (ActiveSet checks both when it builds them).
struct BandEntry {         // no initialisers: millions are allocated, then each written once
  std::uint32_t position;  // in the active set's visiting order
  std::uint32_t quad_begin : 24;
  std::uint32_t quad_count : 8;  // at least 1
};
static_assert(sizeof(BandEntry) == 8);
inline constexpr std::size_t kMaxSliceQuads = std::size_t(1) << 24, kMaxEntryQuads = 255;
// One visit as the y stages see it: its row sums over the band (G for the projection, B for the
// back-projection; pointing at the band's first row, with kQuad rows of margin on either side),
// its entries and its slice's y quads (first rows on the sensor, weights).
struct RowJob {
  float* sums;
  const BandEntry* entries;
  std::size_t n;
  const int* first;
  const float* w;
};

// The x stages work on images in "row lanes": each block of kSubRows sensor rows stored column
// by column, the block's kSubRows pixels of one column side by side, so pixel (r, c) is at
// ((r / kSubRows) * width + c) * kSubRows + r % kSubRows. One x weight then meets all of a
// block's rows in one 16-lane vector operation (one AVX-512 register, two AVX2 ones) instead of
// one 4-pixel quad per row.
//
// `count` image rows from `rows` -> row lanes from `lanes`; the rest of the last block is 0.
void rows_to_lanes(const float* rows, std::size_t width, int count, float* lanes);
// The way back: row lanes from `lanes` -> `count` image rows from `rows`.
void lanes_to_rows(const float* lanes, std::size_t width, int count, float* rows);

// The dispatched kernels (GCC's function multiversioning, resolved once at load time): one call
// per chunk of visits in a band, so the loops over blocks, visits and weights run inside the
// chosen build. Every build does the same float operations in the same order on each lane (a
// multiply, then an add; core/recon is built with -ffp-contract=off, so nothing is fused), so
// all give the same bits. A zero weight (a quad's padding) is skipped: it would add +0.
//
// Projection stage 2: lanes(r, ·) += G(r) Ax over the band's blocks of kSubRows rows that a
// visit reaches, resetting G there. `band` points at the band's first block; every pixel gets
// its visits' additions in visiting order, its quads' in quad order.
void add_columns(float* band, std::size_t width, int words, const ColumnJob* jobs, int count);
// Back-projection stage 1: B[r] = Σ_col Ax r(r, col) over the blocks a visit reaches, from the
// lanes image whose band starts at `band`; rows the visit does not reach are set to 0. Each
// row's sum in dot_quads order (below).
void dot_columns(const float* band, std::size_t width, int words, const ColumnJob* jobs, int count);

// Projection stage 1: G(row) += s Ay(row) for each job's entries in order, s = scaled[position],
// for the band starting at sensor row r0. Every row gets its entries' products in entry order,
// its quads' in quad order; a quad's zero lanes add s 0 = +0 (s >= 0), which leaves every sum as
// it was, so each row gets the same additions as row by row.
void add_rows(const RowJob* jobs, int count, int r0, const float* scaled);
// Back-projection stage 2: sums[position - first] += Σ_row Ay(row) B(row) for each job's entries,
// the entry's sum over the band taken in double (products of floats are exact), quad after quad
// and lane after lane from +0, then added to its sum: one fixed order in every build. `sums` holds
// the positions from `first` on (a strip's voxels).
void dot_rows(const RowJob* jobs, int count, int r0, double* sums, std::uint32_t first);

// The eq 13 normalisers' first stage: out[x] = Σ_col Ax_x(col) row(col) for every voxel x of a
// slice (its quads [start[x], start[x + 1])), for two rows at once (row_b null: one row). Each
// sum runs lane j of the even quads and of the odd ones in separate accumulators, then even +
// odd and the lanes pairwise; the same bits in every build.
void dot_slice_rows(const float* row_a, const float* row_b, const std::size_t* start, const int* first, const float* w,
                    int nx, double* out_a, double* out_b);

// image[i] *= white[i] over n pixels.
void white_band(float* image, const float* white, std::size_t n);

// What MART's log-ratio of a pixel is made of (all arrays over the sensor's pixels).
struct LogRatioInputs {
  const float* projection;  // P: the volume's projection
  const float* data;        // I: the recorded image
  const float* log_data;    // ln I where I > 0
  const float* white;       // the white image: 0 between microlens images
  const float* scale;       // a factor per pixel, or null: 1
  float max_log;            // bound on |log-ratio|
  float log_floor;          // ln of the floor a dark pixel (I = 0) recorded at most
  float dark_floor;         // that floor
  float tiny;               // P below it is taken as it inside the logarithm
};
// ratio[i] for pixels [i0, i1): 0 where the white image is 0 (no voxel sees the pixel); for a lit
// pixel k ln(I/P) clamped to ±max_log (0 where P = 0); for a dark one k max(ln(floor/P), -max_log)
// where P > floor, else 0 (it pulls the voxels that claim more light there down, never up). The
// logarithm is SLEEF's deterministic SSE2 one (3.5 ulp): the same bits on every x86-64 CPU.
// `ratio` may be in.projection (MART writes the log-ratios over the projection).
void log_ratios(const LogRatioInputs& in, std::size_t i0, std::size_t i1, float* ratio);

// out[i] = ln values[i] where values[i] > 0, else 0, for [i0, i1), with the logarithm log_ratios and
// extrapolate take: a pixel its projection matches gets a log-ratio of exactly 0, a voxel unchanged
// since then a momentum of exactly 0.
void log_or_zero(const float* values, std::size_t i0, std::size_t i1, float* out);

// MART's multiplicative update (eq 9) on voxels [i0, i1), arrays over the active voxels: e[i] =
// e[i] exp(mu update[i]), the exponent bounded by ±max_log, the result flushed to 0 below `tiny` and
// capped at `huge`. SLEEF's exp, as extrapolate's.
struct MultiplicativeUpdate {
  float* e;
  const float* update;
  float mu, max_log, tiny, huge;
};
void multiply_by_exp(const MultiplicativeUpdate& u, std::size_t i0, std::size_t i1);

// The multiplicative line of sight's pixel logarithms for [i0, i1): out[i] = ln max(data[i], tiny)
// white[i] for a lit pixel, log_floor white[i] for a dark one (data 0). SLEEF's ln, as log_ratios.
void log_pixels(const float* data, const float* white, float log_floor, float tiny, std::size_t i0, std::size_t i1,
                float* out);

// Nesterov's step of accelerated MART on voxels [i0, i1), arrays over the active voxels: y = x_k
// (x_k / x_(k-1))^beta, taken on ln E. `e` holds x_k and gets y; `last` and `log_last` hold x_(k-1)
// and its ln and get x_k and its ln; `momentum` gets ln x_k - ln x_(k-1) (0 where either is 0).
// The exponent is bounded by ±max_log and y flushed to 0 below `tiny`, capped at `huge`. SLEEF's
// log and exp, as log_ratios.
struct Extrapolation {
  float* e;
  float* last;
  float* log_last;
  float* momentum;
  float beta, max_log, tiny, huge;
};
void extrapolate(const Extrapolation& x, std::size_t i0, std::size_t i1);

}  // namespace plenopiv::recon::kernels
