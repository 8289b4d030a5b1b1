// Per-vector standard uncertainty from correlation statistics (Wieneke 2015) in 3D, and its
// propagation through the final field's smoothing (Sciacchitano & Wieneke 2016).
#include "core/piv/uncertainty.hpp"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>

#include "core/base/isa.hpp"

namespace plenopiv::piv {
namespace {

constexpr float kNoEstimate = std::numeric_limits<float>::quiet_NaN();

// Eight floats (four doubles): GCC's vector extension, so each target clone of sigma_of_window
// gets its own instructions (SSE, AVX or AVX-512) for the same operations in the same order.
typedef float Lanes8 __attribute__((vector_size(32)));
typedef float Floats4 __attribute__((vector_size(16)));
typedef double Doubles4 __attribute__((vector_size(32)));

// The sum over i < n of what add(i, lanes) adds to eight float lanes (elements i .. i + 7) and,
// past the last whole eight, of tail(i) (a double): the lanes summed in float over blocks of 64
// elements, each block's lanes added into eight double lanes, the tail in double.
template <class Add, class Tail>
[[gnu::always_inline]] inline double blocked_sum(std::size_t n, Add add, Tail tail) {
  constexpr std::size_t block = 64;
  Doubles4 low = {0, 0, 0, 0}, high = low;
  const std::size_t whole = n - n % 8;
  std::size_t i = 0;
  while (i < whole) {
    const std::size_t end = std::min(whole, i + block);
    Lanes8 lanes = {0, 0, 0, 0, 0, 0, 0, 0};
    for (; i < end; i += 8) add(i, lanes);
    Floats4 l, h;
    std::memcpy(&l, &lanes, sizeof l);
    std::memcpy(&h, reinterpret_cast<const char*>(&lanes) + sizeof l, sizeof h);
    low += __builtin_convertvector(l, Doubles4);
    high += __builtin_convertvector(h, Doubles4);
  }
  const Doubles4 both = low + high;
  double sum = (both[0] + both[1]) + (both[2] + both[3]);
  for (; i < n; ++i) sum += tail(i);
  return sum;
}

// sum_i x[i] y[i] over n floats.
[[gnu::always_inline]] inline double dot(const float* x, const float* y, std::size_t n) {
  return blocked_sum(
      n,
      [&](std::size_t i, Lanes8& lanes) {
        Lanes8 u, v;
        std::memcpy(&u, x + i, sizeof u);
        std::memcpy(&v, y + i, sizeof v);
        lanes += u * v;
      },
      [&](std::size_t i) { return double(x[i]) * y[i]; });
}

// sum_i x[i] over n floats.
[[gnu::always_inline]] inline double sum_of(const float* x, std::size_t n) {
  return blocked_sum(
      n,
      [&](std::size_t i, Lanes8& lanes) {
        Lanes8 u;
        std::memcpy(&u, x + i, sizeof u);
        lanes += u;
      },
      [&](std::size_t i) { return double(x[i]); });
}

// sum_i x[i] y[(i + k) mod len] over len floats: x's +k neighbours in y, cyclic over the block.
[[gnu::always_inline]] inline double cyclic_dot(const float* x, const float* y, std::size_t len, std::size_t k) {
  return dot(x, y + k, len - k) + dot(x + (len - k), y, k);
}

// Box sums along one axis of `count` lines of `width` contiguous floats each (rows of a slab, or
// slabs of the window): dst line k = the sum of src lines k - r .. k + r that exist (r < count). A
// running sum, one addition and one subtraction per element whatever r, over whole lines, so that
// every loop is long and vectorises.
[[gnu::always_inline]] inline void slide_lines(const float* __restrict src, float* __restrict dst, std::size_t count,
                                               std::size_t width, std::size_t r) {
  std::copy(src, src + width, dst);
  for (std::size_t o = 1; o <= r; ++o)
    for (std::size_t j = 0; j < width; ++j) dst[j] += src[o * width + j];
  for (std::size_t k = 1; k < count; ++k) {
    const float* previous = dst + (k - 1) * width;
    float* out = dst + k * width;
    const float* enters = k + r < count ? src + (k + r) * width : nullptr;
    const float* leaves = k > r ? src + (k - r - 1) * width : nullptr;
    if (enters && leaves)
      for (std::size_t j = 0; j < width; ++j) out[j] = (previous[j] + enters[j]) - leaves[j];
    else if (enters)
      for (std::size_t j = 0; j < width; ++j) out[j] = previous[j] + enters[j];
    else if (leaves)
      for (std::size_t j = 0; j < width; ++j) out[j] = previous[j] - leaves[j];
    else
      std::copy(previous, previous + width, out);
  }
}

// out[i] = in[i] + (in[i + 1] + in[i - 1]) + ... + (in[i + R] + in[i - R]) for i in [from, from + n).
template <std::size_t R>
[[gnu::always_inline]] inline void sum_pairs(const float* __restrict in, float* __restrict out, std::size_t from,
                                             std::size_t n) {
  for (std::size_t i = from; i < from + n; ++i) {
    float v = in[i];
    for (std::size_t o = 1; o <= R; ++o) v += in[i + o] + in[i - o];
    out[i] = v;
  }
}

// Sums `in` over boxes of (2 r + 1) voxels per axis, clipped at the window's faces, into `out`;
// `tmp` is scratch of the same size. All three are laid out as the window's rows (nx voxels, then
// r[0] zeros: a row's box never reaches the next row) from element r[0] on, with r[0] zeros before
// the first row and after the last: row (z ny + y) starts at r[0] + (z ny + y) (nx + r[0]). Along x
// shifted copies of the whole window are added; along y and z the sums run over whole rows and
// slabs.
[[gnu::always_inline]] inline void box_sum(const float* __restrict in, float* __restrict tmp, float* __restrict out,
                                           const std::array<int, 3>& n, const std::array<int, 3>& r) {
  const std::size_t ny = std::size_t(n[1]), nz = std::size_t(n[2]), rx = std::size_t(r[0]);
  const std::size_t stride = std::size_t(n[0]) + rx, plane = ny * stride, total = nz * plane;
  // Along x (into out): the pads keep rows apart. Each sum adds its pairs in the order
  // in[i] + (in[i + 1] + in[i - 1]) + (in[i + 2] + in[i - 2]) + ..., in one pass for the
  // windows' radii (a pass per pair would store and reload every sum rx times).
  switch (rx) {
    case 1:
      sum_pairs<1>(in, out, rx, total);
      break;
    case 2:
      sum_pairs<2>(in, out, rx, total);
      break;
    case 3:
      sum_pairs<3>(in, out, rx, total);
      break;
    case 4:
      sum_pairs<4>(in, out, rx, total);
      break;
    default:
      for (std::size_t i = rx; i < rx + total; ++i) out[i] = in[i];
      for (std::size_t o = 1; o <= rx; ++o)
        for (std::size_t i = rx; i < rx + total; ++i) out[i] += in[i + o] + in[i - o];
  }
  // Along y (into tmp), slab by slab; along z (into out).
  const std::size_t ry = std::min(std::size_t(r[1]), ny - 1), rz = std::min(std::size_t(r[2]), nz - 1);
  for (std::size_t z = 0; z < nz; ++z) slide_lines(out + rx + z * plane, tmp + rx + z * plane, ny, stride, ry);
  slide_lines(tmp + rx, out + rx, nz, plane, rz);
}

// Copies n floats, 16 and 4 at a time: a window's rows are short, too short for a call to memmove.
[[gnu::always_inline]] inline void copy_floats(const float* __restrict src, std::size_t n, float* __restrict dst) {
  std::size_t i = 0;
  for (; i + 16 <= n; i += 16) std::memcpy(dst + i, src + i, 16 * sizeof(float));
  for (; i + 4 <= n; i += 4) std::memcpy(dst + i, src + i, 4 * sizeof(float));
  for (; i < n; ++i) dst[i] = src[i];
}

// Copies `len` floats of `src` (zeros when null) to `dst` turned left by `turn` (dst[x] =
// src[(x + turn) mod len]; 0: a plain copy).
[[gnu::always_inline]] inline void copy_row(const float* __restrict src, std::size_t len, float* __restrict dst,
                                            std::size_t turn = 0) {
  if (!src) {
    std::fill(dst, dst + len, 0.f);
    return;
  }
  copy_floats(src, turn, dst + (len - turn));
  copy_floats(src + turn, len - turn, dst);
}

// The 3-point Gaussian fit's offset error when C(+1) and C(-1) move apart by `spread` from their
// mean `c_pm` about the peak value `c0` (parabolic where a value is not positive); NaN without
// curvature.
float fit_sigma(double c0, double c_pm, double spread) {
  const double cp = c_pm + 0.5 * spread, cm = c_pm - 0.5 * spread;
  if (c0 > 0 && cm > 0 && cp > 0) {
    const double den = 4 * std::log(c0) - 2 * std::log(cp) - 2 * std::log(cm);
    if (den > 0) return float((std::log(cp) - std::log(cm)) / den);
  }
  const double den = 2 * (2 * c0 - 2 * c_pm);
  return den > 0 ? float(spread / den) : kNoEstimate;
}

// One vector's window pair for correlation_statistics_sigma (its arguments, uncertainty.hpp).
struct SigmaJob {
  std::span<const float> a, b;
  const std::array<int, 3>& shape;
  const std::array<int, 3>& origin;
  const std::array<int, 3>& window;
  int depth_margin;
  const std::array<int, 3>& shift;
  UncertaintyScratch& s;
};

// correlation_statistics_sigma's work, built once per instruction set below.
[[gnu::always_inline]] inline std::array<float, 3> sigma_of_window(const SigmaJob& j) {
  const std::span<const float> a = j.a, b = j.b;
  const std::array<int, 3>& shape = j.shape;
  const std::array<int, 3>& origin = j.origin;
  const std::array<int, 3>& window = j.window;
  const std::array<int, 3>& shift = j.shift;
  const int depth_margin = j.depth_margin;
  UncertaintyScratch& s = j.s;
  // The correlation's domain: the window, `depth_margin` slices more at each depth end.
  const std::array<int, 3> n{window[0], window[1], window[2] + 2 * depth_margin};
  const std::size_t count = std::size_t(n[0]) * n[1] * n[2];
  const std::size_t row_len = std::size_t(n[0]), rows = count / row_len;
  s.a.resize(count);
  s.rolled.resize(count);
  // B goes straight to its place rolled by the shift, cyclically: rolled(x) = b(x + shift), so that
  // the peak's neighbours are x's neighbours.
  const auto wrap = [](int i, int len) { return std::size_t(((i % len) + len) % len); };
  const std::size_t turn = wrap(shift[0], n[0]), sy = wrap(shift[1], n[1]), sz = wrap(shift[2], n[2]);
  const std::size_t plane = std::size_t(shape[0]) * shape[1];
  for (int z = 0; z < n[2]; ++z) {
    const int vz = origin[2] - depth_margin + z;
    const bool in_a = z >= depth_margin && z < depth_margin + window[2], in_volume = vz >= 0 && vz < shape[2];
    // The rolled row that source row (z, y) fills: ((z - sz) mod nz, (y - sy) mod ny).
    const std::size_t rz = (std::size_t(z) + n[2] - sz) % std::size_t(n[2]);
    for (int y = 0; y < n[1]; ++y) {
      const std::size_t row =
          std::size_t(in_volume ? vz : 0) * plane + std::size_t(origin[1] + y) * shape[0] + origin[0];
      const std::size_t o = (std::size_t(z) * n[1] + y) * row_len;
      const std::size_t ry = (std::size_t(y) + n[1] - sy) % std::size_t(n[1]);
      copy_row(in_a ? a.data() + row : nullptr, row_len, s.a.data() + o);
      copy_row(in_volume ? b.data() + row : nullptr, row_len, s.rolled.data() + (rz * n[1] + ry) * row_len, turn);
    }
  }
  // A's mean over its own voxels (zeros around it stay zero), B's over the whole domain (its sum
  // taken over the rolled copy: the same values).
  const double sum_a = sum_of(s.a.data(), count), sum_b = sum_of(s.rolled.data(), count);
  const float mean_a = float(sum_a / (double(window[0]) * window[1] * window[2])),
              mean_b = float(sum_b / double(count));
  for (std::size_t q = std::size_t(depth_margin) * n[0] * n[1]; q < std::size_t(depth_margin + window[2]) * n[0] * n[1];
       ++q)
    s.a[q] -= mean_a;
  for (float& v : s.rolled) v -= mean_b;
  const float* pa = s.a.data();
  const float* pb = s.rolled.data();
  // C at the peak and at its cyclic +-1 neighbours, as long dots over the flattened windows: along
  // x the neighbour of a row's last voxel is its first, not the next row's; along y a slab's last
  // row wraps to its first; along z the last slab to the first.
  const std::size_t last = row_len - 1, slab_size = row_len * std::size_t(n[1]);
  const double c0 = dot(pa, pb, count);
  std::array<double, 3> c_plus{dot(pa, pb + 1, count - 1), 0, 0}, c_minus{dot(pa + 1, pb, count - 1), 0, 0};
  for (std::size_t row = 0; row < count; row += row_len) {
    if (row + row_len < count) {
      c_plus[0] -= double(pa[row + last]) * pb[row + row_len];
      c_minus[0] -= double(pa[row + row_len]) * pb[row + last];
    }
    c_plus[0] += double(pa[row + last]) * pb[row];
    c_minus[0] += double(pa[row]) * pb[row + last];
  }
  for (std::size_t slab = 0; slab < count; slab += slab_size) {
    c_plus[1] += cyclic_dot(pa + slab, pb + slab, slab_size, row_len);
    c_minus[1] += cyclic_dot(pb + slab, pa + slab, slab_size, row_len);
  }
  c_plus[2] = cyclic_dot(pa, pb, count, slab_size);
  c_minus[2] = cyclic_dot(pb, pa, count, slab_size);
  // The box: about two Gaussian widths of the correlation peak per axis, sigma_c^2 = -1 / (the
  // curvature of ln C), at least 1 voxel and at most a quarter of the window.
  std::array<int, 3> radius{1, 1, 1};
  for (int axis = 0; axis < 3; ++axis) {
    if (c0 > 0 && c_plus[axis] > 0 && c_minus[axis] > 0) {
      const double curvature = std::log(c_plus[axis]) - 2 * std::log(c0) + std::log(c_minus[axis]);
      if (curvature < 0) radius[axis] = int(std::lround(2 * std::sqrt(-1 / curvature)));
    }
    radius[axis] = std::clamp(radius[axis], 1, std::max(1, window[axis] / 4));
  }
  // dC' in rows padded with radius[0] zeros (box_sum's layout); the pads stay zero, so the box sums'
  // values there are multiplied by zeros.
  const std::size_t rx = std::size_t(radius[0]), stride = row_len + rx;
  // Only the pads are zeroed here: every axis below writes all of each row.
  s.delta.resize(rows * stride + 2 * rx);
  std::fill(s.delta.begin(), s.delta.begin() + std::ptrdiff_t(rx), 0.f);
  for (std::size_t r = 0; r < rows; ++r) {
    float* pad = s.delta.data() + rx + r * stride + row_len;
    std::fill(pad, pad + rx, 0.f);
  }
  std::fill(s.delta.end() - std::ptrdiff_t(rx), s.delta.end(), 0.f);
  s.box.resize(s.delta.size());
  s.line.resize(s.delta.size());
  std::array<float, 3> sigma{};
  for (int axis = 0; axis < 3; ++axis) {
    // dC'(x) = a(x) b(x + e) - a(x + e) b(x) less its mean, (C(+1) - C(-1)) / count.
    const float m = float((c_plus[axis] - c_minus[axis]) / double(count));
    const std::size_t ny = std::size_t(n[1]), nz = std::size_t(n[2]);
    for (std::size_t z = 0, r = 0; z < nz; ++z)
      for (std::size_t y = 0; y < ny; ++y, ++r) {
        const std::size_t row = r * row_len;
        float* __restrict d = s.delta.data() + rx + r * stride;
        if (axis == 0) {
          for (std::size_t x = 0; x < last; ++x)
            d[x] = (pa[row + x] * pb[row + x + 1] - pa[row + x + 1] * pb[row + x]) - m;
          d[last] = (pa[row + last] * pb[row] - pa[row] * pb[row + last]) - m;
        } else {
          // The row of x's +1 neighbours along y or z, cyclic.
          const std::size_t next =
              (axis == 1 ? z * ny + (y + 1 == ny ? 0 : y + 1) : (z + 1 == nz ? 0 : z + 1) * ny + y) * row_len;
          for (std::size_t x = 0; x < row_len; ++x)
            d[x] = (pa[row + x] * pb[next + x] - pa[next + x] * pb[row + x]) - m;
        }
      }
    box_sum(s.delta.data(), s.line.data(), s.box.data(), n, radius);
    // The pads of dC' are zero: one dot over the padded rows.
    const double spread_sq = dot(s.delta.data() + rx, s.box.data() + rx, rows * stride);
    const double spread = std::sqrt(std::max(0.0, spread_sq));
    sigma[axis] = fit_sigma(c0, 0.5 * (c_plus[axis] + c_minus[axis]), spread);
  }
  return sigma;
}

__attribute__((target("avx512f"))) std::array<float, 3> sigma_avx512(const SigmaJob& j) { return sigma_of_window(j); }
__attribute__((target("avx2"))) std::array<float, 3> sigma_avx2(const SigmaJob& j) { return sigma_of_window(j); }
std::array<float, 3> sigma_baseline(const SigmaJob& j) { return sigma_of_window(j); }

}  // namespace

std::array<float, 3> correlation_statistics_sigma(std::span<const float> a, std::span<const float> b,
                                                  const std::array<int, 3>& shape, const std::array<int, 3>& origin,
                                                  const std::array<int, 3>& window, int depth_margin,
                                                  const std::array<int, 3>& shift, UncertaintyScratch& scratch) {
  return for_isa(sigma_avx512, sigma_avx2, sigma_baseline)({a, b, shape, origin, window, depth_margin, shift, scratch});
}

void smooth_sigma(std::vector<float>& sigma, std::span<const std::uint8_t> valid, std::array<int, 3> count, int passes,
                  const std::array<int, 3>& step, const std::array<int, 3>& window) {
  const std::array<std::size_t, 3> stride{1, std::size_t(count[0]), std::size_t(count[0]) * count[1]};
  static constexpr double w[3] = {0.25, 0.5, 0.25};
  std::vector<float> in;
  for (int pass = 0; pass < passes; ++pass)
    for (int axis = 0; axis < 3; ++axis) {
      const double rho[3] = {1.0, std::max(0.0, 1.0 - double(step[axis]) / window[axis]),
                             std::max(0.0, 1.0 - 2.0 * step[axis] / window[axis])};
      in = sigma;
      const std::size_t st = stride[axis];
      tbb::parallel_for(tbb::blocked_range<std::size_t>(0, in.size()), [&](const auto& r) {
        for (std::size_t node = r.begin(); node < r.end(); ++node) {
          const int c = int((node / st) % std::size_t(count[axis]));
          if (!valid[node] || c == 0 || c == count[axis] - 1 || !valid[node - st] || !valid[node + st]) continue;
          const double s[3] = {in[node - st], in[node], in[node + st]};
          double var = 0;
          for (int i = 0; i < 3; ++i)
            for (int j = 0; j < 3; ++j) var += w[i] * w[j] * rho[std::abs(i - j)] * s[i] * s[j];
          sigma[node] = float(std::sqrt(var));  // NaN in, NaN out
        }
      });
    }
}

std::string correlation_statistics_method(int stride, int smoothing_passes) {
  std::string text = "correlation statistics of the final pass (Wieneke 2015)";
  if (stride > 1) text += " every " + std::to_string(stride) + " nodes per axis, interpolated between";
  if (smoothing_passes > 0)
    text += ", through " + std::to_string(smoothing_passes) + " smoothing pass" + (smoothing_passes > 1 ? "es" : "") +
            " (Sciacchitano & Wieneke 2016)";
  return text + ": the correlation's random error";
}

}  // namespace plenopiv::piv
