// A window pair's cyclic cross-correlation at shift 0 and its six face neighbours, summed directly.
#include "core/piv/direct_correlation.hpp"

#include <algorithm>
#include <cstddef>
#include <cstring>
#include <stdexcept>
#include <string>

#include "core/base/isa.hpp"

namespace plenopiv::piv {
namespace {

struct StarJob {
  const float* a;
  const float* b;
  std::array<int, 3> shape;
  float* out;      // kStarShifts values
  float* scratch;  // a', then b' padded cyclically by one voxel per axis, then kStarShifts rows of sums
};

// Sixteen or eight floats: GCC's vector extension, so each instruction set's build gets its own
// instructions (AVX-512, AVX2 or SSE) for the same operations in the same order per x.
typedef float Lanes16 __attribute__((vector_size(64)));
typedef float Lanes8 __attribute__((vector_size(32)));

template <class V>
[[gnu::always_inline]] inline void load(V& v, const float* p) {
  std::memcpy(&v, p, sizeof v);
}

int wrapped(int i, int n) { return i < 0 ? i + n : (i >= n ? i - n : i); }

// x - mean for the `count` floats of `from`, into `to`.
template <class V>
[[gnu::always_inline]] inline void subtract(const float* from, std::size_t count, float mean, float* to) {
  constexpr std::size_t lanes = sizeof(V) / sizeof(float);
  const V m = V{} + mean;
  std::size_t i = 0;
  for (; i + lanes <= count; i += lanes) {
    V v;
    load(v, from + i);
    v -= m;
    std::memcpy(to + i, &v, sizeof v);
  }
  for (; i < count; ++i) to[i] = from[i] - mean;
}

// Per x of rows of `nx` floats, the sum over the `rows` rows in four interleaved partial sums
// (rows 0, 4, 8, ...; 1, 5, ...; ...) added as (s0 + s1) + (s2 + s3), into `sum`; V lanes at once.
template <class V>
[[gnu::always_inline]] inline void column_sums(const float* v, int nx, std::size_t rows, float* sum) {
  constexpr int lanes = sizeof(V) / sizeof(float);
  const int whole = nx - nx % lanes;
  const std::size_t rows4 = rows - rows % 4;
  for (int x = 0; x < whole; x += lanes) {
    V s[4] = {};
    std::size_t row = 0;
    V w;
    for (; row < rows4; row += 4)
      for (int r = 0; r < 4; ++r) load(w, v + (row + r) * nx + x), s[r] += w;
    for (int r = 0; row < rows; ++row, ++r) load(w, v + row * nx + x), s[r] += w;
    const V total = (s[0] + s[1]) + (s[2] + s[3]);
    std::memcpy(sum + x, &total, sizeof total);
  }
  for (int x = whole; x < nx; ++x) {
    float s[4] = {0, 0, 0, 0};
    std::size_t row = 0;
    for (; row < rows4; row += 4)
      for (int r = 0; r < 4; ++r) s[r] += v[(row + r) * nx + x];
    for (int r = 0; row < rows; ++row, ++r) s[r] += v[row * nx + x];
    sum[x] = (s[0] + s[1]) + (s[2] + s[3]);
  }
}

// The window's mean: column_sums, then over x in double.
template <class V>
[[gnu::always_inline]] inline float mean_of(const float* v, int nx, std::size_t rows, float* sum) {
  column_sums<V>(v, nx, rows, sum);
  double total = 0;
  for (int x = 0; x < nx; ++x) total += sum[x];
  return float(total / (double(nx) * double(rows)));
}

// The star. V: the vector the x lanes are summed in (its width changes which lanes share an
// instruction, not what any lane computes).
template <class V>
[[gnu::always_inline]] inline void star_body(const StarJob& j) {
  constexpr int lanes = sizeof(V) / sizeof(float);
  const int nx = j.shape[0], ny = j.shape[1], nz = j.shape[2], whole = nx - nx % lanes;
  const int px = nx + 2, py = ny + 2, pz = nz + 2;
  const std::size_t count = std::size_t(nx) * ny * nz, rows = std::size_t(ny) * nz;
  const std::size_t row_y = std::size_t(px), row_z = std::size_t(px) * py;
  float* a0 = j.scratch;
  float* padded = a0 + count;                        // [z + 1][y + 1][x + 1]: b'(x, y, z), cyclic per axis
  float* sums = padded + std::size_t(px) * py * pz;  // [star shift][x]
  const float mean_a = mean_of<V>(j.a, nx, rows, sums), mean_b = mean_of<V>(j.b, nx, rows, sums);
  subtract<V>(j.a, count, mean_a, a0);
  for (int z = 0; z < pz; ++z)
    for (int y = 0; y < py; ++y) {
      const float* from = j.b + (std::size_t(wrapped(z - 1, nz)) * ny + std::size_t(wrapped(y - 1, ny))) * nx;
      float* to = padded + (std::size_t(z) * py + y) * px;
      subtract<V>(from, std::size_t(nx), mean_b, to + 1);
      to[0] = from[nx - 1] - mean_b;
      to[nx + 1] = from[0] - mean_b;
    }
  // Every row of a' against the padded rows of b' at the seven shifts: seven independent sums per x,
  // in kStarShifts' order.
  for (int x = 0; x < whole; x += lanes) {
    V acc[kStarShifts] = {};
    for (int z = 0; z < nz; ++z)
      for (int y = 0; y < ny; ++y) {
        V va, vb[kStarShifts];
        load(va, a0 + (std::size_t(z) * ny + y) * nx + x);
        const float* at = padded + (std::size_t(z + 1) * py + std::size_t(y + 1)) * px + 1 + x;
        load(vb[0], at);
        load(vb[1], at - 1);
        load(vb[2], at + 1);
        load(vb[3], at - row_y);
        load(vb[4], at + row_y);
        load(vb[5], at - row_z);
        load(vb[6], at + row_z);
        for (int k = 0; k < kStarShifts; ++k) acc[k] += va * vb[k];
      }
    for (int k = 0; k < kStarShifts; ++k) std::memcpy(sums + std::size_t(k) * nx + x, &acc[k], sizeof(V));
  }
  for (int x = whole; x < nx; ++x) {
    float acc[kStarShifts] = {};
    for (int z = 0; z < nz; ++z)
      for (int y = 0; y < ny; ++y) {
        const float va = a0[(std::size_t(z) * ny + y) * nx + x];
        const float* at = padded + (std::size_t(z + 1) * py + std::size_t(y + 1)) * px + 1 + x;
        acc[0] += va * at[0];
        acc[1] += va * at[-1];
        acc[2] += va * at[1];
        acc[3] += va * *(at - row_y);
        acc[4] += va * *(at + row_y);
        acc[5] += va * *(at - row_z);
        acc[6] += va * *(at + row_z);
      }
    for (int k = 0; k < kStarShifts; ++k) sums[std::size_t(k) * nx + x] = acc[k];
  }
  for (int k = 0; k < kStarShifts; ++k) {
    double total = 0;
    for (int x = 0; x < nx; ++x) total += sums[std::size_t(k) * nx + x];
    j.out[k] = float(total);
  }
}

void star_baseline(const StarJob& j) { star_body<Lanes8>(j); }
__attribute__((target("avx512f"))) void star_avx512(const StarJob& j) { star_body<Lanes16>(j); }
__attribute__((target("avx2"))) void star_avx2(const StarJob& j) { star_body<Lanes8>(j); }

}  // namespace

std::array<float, kStarShifts> correlate_star(std::span<const float> a, std::span<const float> b,
                                              const std::array<int, 3>& shape, std::vector<float>& scratch) {
  const std::size_t count = std::size_t(shape[0]) * shape[1] * shape[2];
  for (int axis = 0; axis < 3; ++axis)
    if (shape[axis] < 3)
      throw std::invalid_argument(std::string("correlate_star: a window of ") + std::to_string(shape[axis]) +
                                  " voxels along " + "xyz"[axis] + " has no two neighbours of shift 0");
  if (a.size() != count || b.size() != count)
    throw std::invalid_argument("correlate_star: the windows' sizes do not match the shape");
  scratch.resize(count + std::size_t(shape[0] + 2) * (shape[1] + 2) * (shape[2] + 2) +
                 std::size_t(kStarShifts) * shape[0]);
  std::array<float, kStarShifts> out;
  for_isa(star_avx512, star_avx2, star_baseline)({a.data(), b.data(), shape, out.data(), scratch.data()});
  return out;
}

}  // namespace plenopiv::piv
