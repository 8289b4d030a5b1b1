// core/piv: correlation, peak fit, interpolation, validation, vorticity and the multi-pass
// correlation against known displacements of particle volumes built here.
#include <gtest/gtest.h>
#include <tbb/global_control.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <complex>
#include <cstring>
#include <limits>
#include <numbers>
#include <random>
#include <stdexcept>
#include <utility>

#include "core/base/errors.hpp"
#include "core/base/isa.hpp"
#include "core/base/yaml_access.hpp"
#include "core/piv/deform.hpp"
#include "core/piv/derived.hpp"
#include "core/piv/direct_correlation.hpp"
#include "core/piv/fft_correlator.hpp"
#include "core/piv/multipass.hpp"
#include "core/piv/peak_fit.hpp"
#include "core/piv/settings.hpp"
#include "core/piv/uncertainty.hpp"
#include "core/piv/validation.hpp"
#include "core/sim/exact_volume.hpp"
#include "core/sim/field_errors.hpp"
#include "core/sim/flows.hpp"
#include "core/sim/particles.hpp"
#include "tests/support/same_bits.hpp"

namespace plenopiv::piv {
namespace {

using P3 = std::array<double, 3>;

// Wide Gaussian blobs (sigma 1 voxel, 5x5x5 support) at voxel coordinates, for the tests of
// interpolation and validation; the accuracy tests use the paper's exact-particle volumes
// (sim::render_exact_volume). With sigma_z > 1, streaks along depth (support +-2 sigma_z), as
// MART reconstructs particles.
Volume blobs(const Grid3& g, const std::vector<P3>& at, double sigma_z = 1) {
  Volume v(g);
  const int reach_z = int(std::ceil(2 * sigma_z));
  for (const P3& p : at) {
    const int cx = int(std::lround(p[0])), cy = int(std::lround(p[1])), cz = int(std::lround(p[2]));
    for (int z = cz - reach_z; z <= cz + reach_z; ++z)
      for (int y = cy - 2; y <= cy + 2; ++y)
        for (int x = cx - 2; x <= cx + 2; ++x) {
          if (x < 0 || y < 0 || z < 0 || x >= g.shape[0] || y >= g.shape[1] || z >= g.shape[2]) continue;
          const double r2 =
              (x - p[0]) * (x - p[0]) + (y - p[1]) * (y - p[1]) + (z - p[2]) * (z - p[2]) / (sigma_z * sigma_z);
          v.at(x, y, z) += float(std::exp(-r2 / 2.0));
        }
  }
  return v;
}

std::vector<P3> random_points(const Grid3& g, int count, unsigned seed) {
  std::mt19937_64 rng(seed);
  std::vector<P3> p(count);
  for (auto& q : p)
    for (int a = 0; a < 3; ++a) q[a] = std::uniform_real_distribution<double>(-4, g.shape[a] + 3)(rng);
  return p;
}

// The kernels' builds this CPU runs, lowest first; prints the ones it cannot test.
std::vector<Isa> builds_to_test() {
  std::vector<Isa> builds;
  for (const Isa build : {Isa::baseline, Isa::avx2, Isa::avx512})
    if (build <= best_isa())
      builds.push_back(build);
    else
      std::printf("this CPU has no %s build to test\n", isa_name(build));
  return builds;
}

Grid3 cube(int n) {
  Grid3 g;
  g.shape = {n, n, n};
  g.spacing_mm = {0.1, 0.1, 0.1};
  return g;
}

TEST(FftCorrelator, IntegerShiftOfARandomWindowPeaksThere) {
  const std::array<int, 3> shape{16, 12, 20};
  FftCorrelator corr(shape);
  auto& ws = corr.workspace();
  std::mt19937 rng(3);
  std::uniform_real_distribution<float> u(0, 1);
  std::vector<float> a(corr.size());
  for (auto& v : a) v = u(rng);
  const int sx = 3, sy = -2, sz = 5;  // b(x) = a(x - s): content moved by +s
  auto wa = ws.window_a();
  auto wb = ws.window_b();
  for (int z = 0; z < shape[2]; ++z)
    for (int y = 0; y < shape[1]; ++y)
      for (int x = 0; x < shape[0]; ++x) {
        const std::size_t i = (std::size_t(z) * shape[1] + y) * shape[0] + x;
        wa[i] = a[i];
        const int xs = (x - sx + shape[0]) % shape[0], ys = (y - sy + shape[1]) % shape[1],
                  zs = (z - sz + shape[2]) % shape[2];
        wb[i] = a[(std::size_t(zs) * shape[1] + ys) * shape[0] + xs];
      }
  const auto peaks = find_peaks(ws.correlate(), shape);
  EXPECT_EQ(std::lround(peaks[0].shift[0]), sx);
  EXPECT_EQ(std::lround(peaks[0].shift[1]), sy);
  EXPECT_EQ(std::lround(peaks[0].shift[2]), sz);
  EXPECT_GT(peak_ratio(peaks), 2.f);
}

// The weighted correlation against a direct evaluation in double: R(s) = sum_k W(C_k) e^(2 pi i k.s / n)
// with C_k = conj(A_k) B_k / n (0 at k = 0), W(C) = C G / |C|^p and G the Gaussian whose peak has
// standard deviation sigma voxels per axis. Odd and even sizes (FFTW's half spectrum and its
// mirrors), x sizes whose half spectrum is 0, 1, 2 vectors of the cross spectrum's row and a rest
// (the mirror read backwards), each of the weighting's paths: p = 1/2 and 1 (square roots) and
// another power; under every build this CPU runs, all with the same bits.
TEST(FftCorrelator, WeightedCorrelationIsTheWhitenedCrossSpectrumsInverse) {
  const Isa chosen = isa();
  const std::vector<Isa> builds = builds_to_test();
  const std::array<double, 3> sigma{1, 0.7, 2};
  for (const std::array<int, 3> shape : {std::array<int, 3>{6, 5, 4}, {16, 3, 2}, {20, 3, 2}, {9, 4, 3}, {17, 2, 3}}) {
    SCOPED_TRACE("shape " + std::to_string(shape[0]) + "x" + std::to_string(shape[1]) + "x" + std::to_string(shape[2]));
    const std::size_t n = std::size_t(shape[0]) * shape[1] * shape[2];
    std::mt19937 rng(11);
    std::uniform_real_distribution<float> u(0, 1);
    std::vector<float> a(n), b(n);
    for (std::size_t i = 0; i < n; ++i) {
      a[i] = u(rng);
      b[i] = u(rng);
    }
    const auto index = [&](int x, int y, int z) { return (std::size_t(z) * shape[1] + y) * shape[0] + x; };
    const double two_pi = 2 * std::numbers::pi;
    // A_k and B_k by the definition.
    std::vector<std::complex<double>> spectrum_a(n), spectrum_b(n);
    for (int kz = 0; kz < shape[2]; ++kz)
      for (int ky = 0; ky < shape[1]; ++ky)
        for (int kx = 0; kx < shape[0]; ++kx)
          for (int z = 0; z < shape[2]; ++z)
            for (int y = 0; y < shape[1]; ++y)
              for (int x = 0; x < shape[0]; ++x) {
                const double phase =
                    -two_pi * (double(kx) * x / shape[0] + double(ky) * y / shape[1] + double(kz) * z / shape[2]);
                const std::complex<double> e = std::polar(1.0, phase);
                spectrum_a[index(kx, ky, kz)] += double(a[index(x, y, z)]) * e;
                spectrum_b[index(kx, ky, kz)] += double(b[index(x, y, z)]) * e;
              }
    const auto frequency = [](int k, int len) { return double(k <= len / 2 ? k : k - len) / len; };
    FftCorrelator corr(shape);
    for (const double p : {0.5, 1.0, 0.3}) {
      SCOPED_TRACE("power " + std::to_string(p));
      std::vector<std::complex<double>> weighted(n);
      for (int kz = 0; kz < shape[2]; ++kz)
        for (int ky = 0; ky < shape[1]; ++ky)
          for (int kx = 0; kx < shape[0]; ++kx) {
            const std::size_t k = index(kx, ky, kz);
            if (k == 0) continue;
            const std::complex<double> c = std::conj(spectrum_a[k]) * spectrum_b[k] / double(n);
            const double f[3] = {frequency(kx, shape[0]), frequency(ky, shape[1]), frequency(kz, shape[2])};
            double e = 0;
            for (int axis = 0; axis < 3; ++axis) e += sigma[axis] * sigma[axis] * f[axis] * f[axis];
            weighted[k] = c * std::exp(-two_pi * std::numbers::pi * e) / std::pow(std::abs(c), p);
          }
      std::vector<double> expected(n);
      double largest = 0;
      for (int sz = 0; sz < shape[2]; ++sz)
        for (int sy = 0; sy < shape[1]; ++sy)
          for (int sx = 0; sx < shape[0]; ++sx) {
            std::complex<double> sum = 0;
            for (int kz = 0; kz < shape[2]; ++kz)
              for (int ky = 0; ky < shape[1]; ++ky)
                for (int kx = 0; kx < shape[0]; ++kx)
                  sum += weighted[index(kx, ky, kz)] *
                         std::polar(1.0, two_pi * (double(kx) * sx / shape[0] + double(ky) * sy / shape[1] +
                                                   double(kz) * sz / shape[2]));
            expected[index(sx, sy, sz)] = sum.real();
            largest = std::max(largest, std::abs(sum.real()));
          }
      ASSERT_GT(largest, 0.0);
      const SpectralWeights weights(shape, p, sigma);
      std::vector<float> first_build;
      for (const Isa build : builds) {
        SCOPED_TRACE(isa_name(build));
        use_isa(build);
        auto& ws = corr.workspace();
        std::copy(a.begin(), a.end(), ws.window_a().begin());
        std::copy(b.begin(), b.end(), ws.window_b().begin());
        const std::span<const float> r = ws.correlate(&weights);
        double worst = 0;
        for (std::size_t i = 0; i < n; ++i) worst = std::max(worst, std::abs(double(r[i]) - expected[i]));
        EXPECT_LT(worst, 1e-5 * largest) << worst / largest;
        if (first_build.empty())
          first_build.assign(r.begin(), r.end());
        else
          EXPECT_TRUE(std::equal(r.begin(), r.end(), first_build.begin())) << "not the bits of the first build";
      }
    }
  }
  use_isa(chosen);
}

// A sampled Gaussian correlation peak: the 3-point Gaussian fit is exact for it.
std::vector<float> gaussian_peak(const std::array<int, 3>& s, const P3& centre, double sigma, double floor_value = 0) {
  std::vector<float> c(std::size_t(s[0]) * s[1] * s[2]);
  for (int z = 0; z < s[2]; ++z)
    for (int y = 0; y < s[1]; ++y)
      for (int x = 0; x < s[0]; ++x) {
        const std::array<int, 3> i{x, y, z};
        double r2 = 0;
        for (int a = 0; a < 3; ++a) {
          double d = i[a] - centre[a];
          d -= s[a] * std::round(d / s[a]);  // cyclic distance
          r2 += d * d;
        }
        c[(std::size_t(z) * s[1] + y) * s[0] + x] = float(std::exp(-r2 / (2 * sigma * sigma)) + floor_value);
      }
  return c;
}

TEST(PeakFit, GaussianFitIsExactForAGaussianPeak) {
  const std::array<int, 3> s{16, 16, 24};
  const auto c = gaussian_peak(s, {2.3, 16 - 3.4, 5.45}, 1.2);
  const Peak p = fit_peak(c, s, {2, 13, 5});
  EXPECT_NEAR(p.shift[0], 2.3, 1e-4);
  EXPECT_NEAR(p.shift[1], -3.4, 1e-4);
  EXPECT_NEAR(p.shift[2], 5.45, 1e-4);
  EXPECT_EQ(p.flags, 0);
}

TEST(PeakFit, NonPositiveNeighbourFallsBackToParabolaAndSaysSo) {
  const std::array<int, 3> s{8, 8, 8};
  auto c = gaussian_peak(s, {1.2, 1, 1}, 0.8, -0.5);  // below zero beside the peak
  const Peak p = fit_peak(c, s, {1, 1, 1});
  EXPECT_TRUE(p.flags & flag_parabolic);
  EXPECT_GT(p.shift[0], 1.0f);
  EXPECT_LT(p.shift[0], 1.5f);
}

TEST(PeakFit, PeakOnTheBorderUsesTheCentroidAndSaysSo) {
  const std::array<int, 3> s{8, 8, 8};
  const auto c = gaussian_peak(s, {4.0, 0, 0}, 1.0);  // shift -4 = +4: ambiguous
  const Peak p = fit_peak(c, s, {4, 0, 0});
  EXPECT_TRUE(p.flags & flag_centroid);
  EXPECT_NEAR(std::abs(p.shift[0]), 4.0, 1e-5);
  EXPECT_NEAR(p.shift[1], 0.0, 1e-5);
}

TEST(PeakFit, ThreeHighestMaximaInOrder) {
  const std::array<int, 3> s{16, 16, 16};
  auto c = gaussian_peak(s, {3, 4, 5}, 0.7);
  const auto second = gaussian_peak(s, {10, 2, 1}, 0.7);
  const auto third = gaussian_peak(s, {0, 12, 9}, 0.7);
  for (std::size_t i = 0; i < c.size(); ++i) c[i] += 0.6f * second[i] + 0.3f * third[i];
  const auto p = find_peaks(c, s);
  EXPECT_NEAR(p[0].shift[0], 3, 1e-3);
  EXPECT_NEAR(p[1].shift[0], -6, 1e-3);  // index 10 of 16 is shift -6
  EXPECT_NEAR(p[2].shift[1], -4, 1e-3);
  EXPECT_NEAR(peak_ratio(p), 1 / 0.6, 1e-3);
}

// find_peaks against a search of every voxel: a local maximum beats each of its 26 cyclic neighbours,
// strictly those before it in the array (so a plateau counts once, at its first voxel) and not
// those after it; the three highest positive ones, ties to the lower index. Planes with many ties
// and plateaus (values on a coarse grid), negative values, NaN, and sizes that are not multiples of 4.
// Under each build this CPU runs: a 16-voxel row takes AVX-512's or AVX2's pre-test, other rows SSE's;
// planes with one lit row of 16, 8 or 7 voxels (a shuffle of as many levels, dark rows about it)
// test every voxel's x neighbours, at the ends and joins of a row's vector pre-tests among them.
TEST(PeakFit, FindPeaksIsTheSearchOfEveryVoxel) {
  const Isa chosen = isa();
  const std::vector<Isa> builds = builds_to_test();
  std::mt19937 rng(5);
  const std::array<std::array<int, 3>, 8> shapes{
      {{16, 16, 8}, {7, 5, 3}, {9, 12, 6}, {32, 32, 16}, {5, 3, 4}, {16, 3, 3}, {8, 3, 3}, {7, 3, 3}}};
  int planes = 0, with_three = 0;
  for (const auto& shape : shapes) {
    const bool one_row = shape[1] == 3 && shape[2] == 3;
    for (int trial = 0; trial < (one_row ? 400 : 60); ++trial, ++planes) {
      const std::size_t n = std::size_t(shape[0]) * shape[1] * shape[2];
      std::vector<float> c(n);
      const int levels = trial % 3 == 0 ? 4 : trial % 3 == 1 ? 50 : 100000;
      std::uniform_int_distribution<int> level(-levels / 2, levels);
      for (float& v : c) v = float(level(rng)) / float(levels);
      if (trial % 5 == 4) c[std::size_t(level(rng) + levels / 2) % n] = std::numeric_limits<float>::quiet_NaN();
      if (trial % 7 == 6) std::fill(c.begin(), c.end(), 0.25f);  // one plateau over the whole plane
      if (one_row) {
        std::fill(c.begin(), c.end(), 0.f);
        float* row = c.data() + 4 * shape[0];  // y 1, z 1
        for (int x = 0; x < shape[0]; ++x) row[x] = float(x + 1) / float(shape[0]);
        std::shuffle(row, row + shape[0], rng);
      }
      const auto at = [&](int x, int y, int z) {
        const auto wrap = [](int i, int len) { return (i % len + len) % len; };
        return (std::size_t(wrap(z, shape[2])) * shape[1] + wrap(y, shape[1])) * shape[0] + wrap(x, shape[0]);
      };
      std::vector<std::pair<float, std::size_t>> maxima;
      for (int z = 0; z < shape[2]; ++z)
        for (int y = 0; y < shape[1]; ++y)
          for (int x = 0; x < shape[0]; ++x) {
            const float v = c[at(x, y, z)];
            if (!(v > 0)) continue;
            bool local = true;
            for (int dz = -1; dz <= 1 && local; ++dz)
              for (int dy = -1; dy <= 1 && local; ++dy)
                for (int dx = -1; dx <= 1 && local; ++dx) {
                  if (!dx && !dy && !dz) continue;
                  const bool before = (dz * shape[1] + dy) * shape[0] + dx < 0;
                  const float w = c[at(x + dx, y + dy, z + dz)];
                  local = before ? !(w >= v) : !(w > v);
                }
            if (local) maxima.push_back({v, at(x, y, z)});
          }
      std::sort(maxima.begin(), maxima.end(), [](const auto& p, const auto& q) {
        return p.first > q.first || (p.first == q.first && p.second < q.second);
      });
      for (const Isa build : builds) {
        use_isa(build);
        const auto found = find_peaks(c, shape);
        for (std::size_t i = 0; i < 3; ++i) {
          SCOPED_TRACE(std::string(isa_name(build)) + ", shape " + std::to_string(shape[0]) + "x" +
                       std::to_string(shape[1]) + "x" + std::to_string(shape[2]) + ", trial " + std::to_string(trial) +
                       ", peak " + std::to_string(i));
          if (i >= maxima.size()) {
            EXPECT_EQ(found[i].value, 0.f);
            continue;
          }
          const std::size_t k = maxima[i].second;
          const int x = int(k % std::size_t(shape[0])), y = int(k / std::size_t(shape[0]) % std::size_t(shape[1])),
                    z = int(k / (std::size_t(shape[0]) * shape[1]));
          const Peak expected = fit_peak(c, shape, {x, y, z});
          EXPECT_EQ(found[i].value, expected.value);
          EXPECT_EQ(found[i].shift, expected.shift);
          EXPECT_EQ(found[i].flags, expected.flags);
        }
      }
      with_three += maxima.size() >= 3;
    }
  }
  use_isa(chosen);
  EXPECT_GT(with_three, planes / 2);  // the ranking of three is what is compared, most of the time
}

TEST(Sinc7, ExactAtVoxelsKeepsConstantsAndInterpolatesSmoothSignals) {
  const std::array<int, 3> s{24, 24, 24};
  std::vector<float> v(std::size_t(s[0]) * s[1] * s[2]);
  auto f = [](double x, double y, double z) {
    return std::sin(2 * M_PI * x / 12) * std::cos(2 * M_PI * y / 14) + 0.5 * std::sin(2 * M_PI * z / 10);
  };
  for (int z = 0; z < s[2]; ++z)
    for (int y = 0; y < s[1]; ++y)
      for (int x = 0; x < s[0]; ++x) v[(std::size_t(z) * s[1] + y) * s[0] + x] = float(f(x, y, z));
  EXPECT_NEAR(sample_sinc7(v, s, 10, 11, 12), f(10, 11, 12), 1e-6);
  double worst = 0, worst_linear = 0;
  for (double t = 0; t < 1; t += 0.07) {
    const double x = 10 + t, y = 12 - 0.6 * t, z = 11 + 0.3 * t;
    worst = std::max(worst, std::abs(sample_sinc7(v, s, x, y, z) - f(x, y, z)));
    // Trilinear for comparison.
    const int x0 = int(x), y0 = int(y), z0 = int(z);
    double lin = 0;
    for (int c = 0; c < 8; ++c) {
      const int dx = c & 1, dy = c >> 1 & 1, dz = c >> 2 & 1;
      lin += (dx ? x - x0 : 1 - (x - x0)) * (dy ? y - y0 : 1 - (y - y0)) * (dz ? z - z0 : 1 - (z - z0)) *
             f(x0 + dx, y0 + dy, z0 + dz);
    }
    worst_linear = std::max(worst_linear, std::abs(lin - f(x, y, z)));
  }
  std::printf("sinc7 worst error %.2e, trilinear %.2e\n", worst, worst_linear);
  // The 7-tap sinc within 5e-3 of a smooth field (periods of 10-14 voxels), four times better
  // than trilinear interpolation.
  EXPECT_LT(worst, 5e-3) << "measured 2.5e-3 (trilinear: 1.1e-2)";
  std::vector<float> ones(v.size(), 2.5f);
  EXPECT_NEAR(sample_sinc7(ones, s, 9.37, 10.81, 12.5), 2.5, 1e-5);
}

// With either interpolator (the cubic one a little less closely).
TEST(Deform, SymmetricDeformationMovesBothHalfway) {
  const Grid3 g = cube(32);
  const P3 d{1.6, -0.8, 2.4};
  const std::vector<P3> pa{{15, 16, 14}};
  const std::vector<P3> pb{{15 + d[0], 16 + d[1], 14 + d[2]}};
  const Volume a = blobs(g, pa), b = blobs(g, pb);
  NodeField pred({2, 2, 2}, {0, 0, 0}, {31, 31, 31});
  for (int c = 0; c < 3; ++c) pred.d[c].assign(8, float(d[c]));
  for (const Interpolation how : {Interpolation::sinc, Interpolation::cubic}) {
    const char* name = how == Interpolation::sinc ? "sinc" : "cubic";
    std::vector<float> da(a.data.size()), db(b.data.size());
    deform_pair(a.data, b.data, g.shape, pred, da, db, how);
    // Both should now hold the blob at the midpoint: compare with a blob rendered there.
    const Volume mid = blobs(g, {{15 + d[0] / 2, 16 + d[1] / 2, 14 + d[2] / 2}});
    double err_a = 0, err_b = 0, norm = 0;
    for (std::size_t i = 0; i < da.size(); ++i) {
      err_a += (da[i] - mid.data[i]) * (da[i] - mid.data[i]);
      err_b += (db[i] - mid.data[i]) * (db[i] - mid.data[i]);
      norm += mid.data[i] * mid.data[i];
    }
    std::printf("%s: relative L2 error a %.4f, b %.4f\n", name, std::sqrt(err_a / norm), std::sqrt(err_b / norm));
    EXPECT_LT(std::sqrt(err_a / norm), how == Interpolation::sinc ? 0.05 : 0.1) << name;
    EXPECT_LT(std::sqrt(err_b / norm), how == Interpolation::sinc ? 0.05 : 0.1) << name;
  }
}

// Keys' cubic convolution reproduces a quadratic field exactly (away from the faces, where the
// voxels beyond count as zero), and a shift of zero gives the volume back.
TEST(Deform, CubicReproducesAQuadraticAndAZeroShift) {
  const std::array<int, 3> shape{20, 18, 16};
  const auto f = [](double x, double y, double z) { return 0.3 * x * x - 0.2 * x * y + 0.1 * z * z + y - 2 * z + 5; };
  std::vector<float> v(std::size_t(shape[0]) * shape[1] * shape[2]);
  for (int z = 0; z < shape[2]; ++z)
    for (int y = 0; y < shape[1]; ++y)
      for (int x = 0; x < shape[0]; ++x) v[(std::size_t(z) * shape[1] + y) * shape[0] + x] = float(f(x, y, z));
  NodeField pred({2, 2, 2}, {0, 0, 0}, {19, 17, 15});
  const std::array<float, 3> d{0.74f, -1.38f, 0.5f};
  for (int c = 0; c < 3; ++c) pred.d[c].assign(8, d[c]);
  std::vector<float> da(v.size()), db(v.size());
  deform_pair(v, v, shape, pred, da, db, Interpolation::cubic);
  double worst = 0;
  for (int z = 4; z < shape[2] - 4; ++z)
    for (int y = 4; y < shape[1] - 4; ++y)
      for (int x = 4; x < shape[0] - 4; ++x) {
        const std::size_t i = (std::size_t(z) * shape[1] + y) * shape[0] + x;
        const double want_a = f(x - d[0] / 2, y - d[1] / 2, z - d[2] / 2),
                     want_b = f(x + d[0] / 2, y + d[1] / 2, z + d[2] / 2);
        worst =
            std::max({worst, std::abs(da[i] - want_a) / std::abs(want_a), std::abs(db[i] - want_b) / std::abs(want_b)});
      }
  EXPECT_LT(worst, 1e-5) << "float rounding only";
  for (int c = 0; c < 3; ++c) pred.d[c].assign(8, 0.f);
  deform_pair(v, v, shape, pred, da, db, Interpolation::cubic);
  EXPECT_EQ(da, v);
  EXPECT_EQ(db, v);
}

// Two volumes of `count` voxels of uniform noise in [0, 1), drawn from `rng` voxel by voxel (a's,
// then b's), for the deformation's bit-for-bit tests.
std::pair<std::vector<float>, std::vector<float>> noise_pair(std::size_t count, std::mt19937& rng) {
  std::uniform_real_distribution<float> value(0.f, 1.f);
  std::vector<float> a(count), b(count);
  for (std::size_t i = 0; i < count; ++i) {
    a[i] = value(rng);
    b[i] = value(rng);
  }
  return {std::move(a), std::move(b)};
}

// Voxels beyond the faces count as zero, with the arithmetic of a stencil inside: the volume
// deformed as it is and a copy padded with zeros (the predictor moved with it) give the same bits
// over the original voxels, though there every stencil near a face lies inside. With either
// interpolator, and a predictor varying enough to mix both kinds of stencil in one block.
TEST(Deform, AStencilPastAFaceGivesTheBitsOfAZeroPaddedVolume) {
  const std::array<int, 3> shape{23, 14, 12};
  constexpr int pad = 8;
  const std::array<int, 3> padded{shape[0] + 2 * pad, shape[1] + 2 * pad, shape[2] + 2 * pad};
  std::mt19937 rng(7);
  const auto [a, b] = noise_pair(std::size_t(shape[0]) * shape[1] * shape[2], rng);
  std::uniform_real_distribution<float> shift(-3.f, 3.f);
  const auto index = [](const std::array<int, 3>& s, int x, int y, int z) {
    return (std::size_t(z) * s[1] + y) * s[0] + x;
  };
  std::vector<float> pa(std::size_t(padded[0]) * padded[1] * padded[2], 0.f), pb(pa.size(), 0.f);
  for (int z = 0; z < shape[2]; ++z)
    for (int y = 0; y < shape[1]; ++y)
      for (int x = 0; x < shape[0]; ++x) {
        pa[index(padded, x + pad, y + pad, z + pad)] = a[index(shape, x, y, z)];
        pb[index(padded, x + pad, y + pad, z + pad)] = b[index(shape, x, y, z)];
      }
  NodeField pred({4, 3, 3}, {0, 0, 0}, {7, 6.5, 5.5});
  for (int c = 0; c < 3; ++c)
    for (float& d : pred.d[c]) d = shift(rng);
  NodeField pred_padded = pred;
  pred_padded.first = {pad, pad, pad};
  for (const Interpolation how : {Interpolation::sinc, Interpolation::cubic}) {
    const char* name = how == Interpolation::sinc ? "sinc" : "cubic";
    std::vector<float> da(a.size()), db(a.size()), pda(pa.size()), pdb(pa.size());
    deform_pair(a, b, shape, pred, da, db, how);
    deform_pair(pa, pb, padded, pred_padded, pda, pdb, how);
    std::size_t differ = 0, nonzero = 0;
    for (int z = 0; z < shape[2]; ++z)
      for (int y = 0; y < shape[1]; ++y)
        for (int x = 0; x < shape[0]; ++x) {
          const std::size_t i = index(shape, x, y, z), j = index(padded, x + pad, y + pad, z + pad);
          differ +=
              std::memcmp(&da[i], &pda[j], sizeof(float)) != 0 || std::memcmp(&db[i], &pdb[j], sizeof(float)) != 0;
          nonzero += da[i] != 0.f;
        }
    EXPECT_EQ(differ, 0u) << name;
    EXPECT_GT(nonzero, a.size() / 2) << name << ": the deformed volume holds the signal";
  }
}

// Each deformed voxel against its sample computed alone: the sinc's by sample_sinc7, Keys' cubic by
// its definition summed in sum_rows' order (per x tap over the rows z-major, then the x weights),
// bit for bit, under each build this CPU runs. A constant predictor puts whole rows of voxels side
// by side (the path that sums a build's register of voxels at once), a smooth one mixes that path
// with its halves and the per-sample one where its rounding changes, a random one takes the
// per-sample path; the rows' 53 voxels end in a part register.
TEST(Deform, EveryVoxelHasTheBitsOfItsOwnSample) {
  const std::array<int, 3> shape{53, 21, 17};
  std::mt19937 rng(11);
  const auto [a, b] = noise_pair(std::size_t(shape[0]) * shape[1] * shape[2], rng);
  std::uniform_real_distribution<float> shift(-3.f, 3.f);
  const auto voxel = [&](const std::vector<float>& v, int x, int y, int z) {
    if (x < 0 || y < 0 || z < 0 || x >= shape[0] || y >= shape[1] || z >= shape[2]) return 0.f;
    return v[(std::size_t(z) * shape[1] + y) * shape[0] + x];
  };
  // Keys' cubic at p along one axis: the first voxel and the 4 weights (deform.hpp).
  const auto keys = [](double p, int& base, float* w) {
    const double f0 = std::floor(p), f = p - f0, g = 1 - f;
    base = int(f0) - 1;
    w[0] = float(((-0.5 * f + 1) * f - 0.5) * f);
    w[1] = float((1.5 * f - 2.5) * f * f + 1);
    w[2] = float((1.5 * g - 2.5) * g * g + 1);
    w[3] = float(((-0.5 * g + 1) * g - 0.5) * g);
  };
  const auto cubic = [&](const std::vector<float>& v, double px, double py, double pz) {
    int base[3];
    float w[3][4];
    keys(px, base[0], w[0]);
    keys(py, base[1], w[1]);
    keys(pz, base[2], w[2]);
    float acc[4] = {0, 0, 0, 0};
    for (int kz = 0; kz < 4; ++kz)
      for (int ky = 0; ky < 4; ++ky) {
        const float wzy = w[2][kz] * w[1][ky];
        for (int k = 0; k < 4; ++k) acc[k] += wzy * voxel(v, base[0] + k, base[1] + ky, base[2] + kz);
      }
    float total = 0;
    for (int k = 0; k < 4; ++k) total += w[0][k] * acc[k];
    return total;
  };
  NodeField constant({2, 2, 2}, {0, 0, 0}, {52, 20, 16}), smooth({5, 4, 4}, {0, 0, 0}, {13, 6.67, 5.33}),
      random({5, 4, 4}, {0, 0, 0}, {13, 6.67, 5.33});
  for (int c = 0; c < 3; ++c) {
    constant.d[c].assign(8, std::array<float, 3>{1.37f, -0.62f, 2.21f}[c]);
    for (std::size_t n = 0; n < smooth.d[c].size(); ++n) {
      const int i = int(n % 5), j = int(n / 5 % 4), k = int(n / 20);
      smooth.d[c][n] = float(0.8 * (c + 1) - 0.3 * c + 0.12 * i - 0.07 * j + 0.09 * k);
    }
    for (float& d : random.d[c]) d = shift(rng);
  }
  const Isa chosen = isa();
  for (const Isa build : builds_to_test()) {
    use_isa(build);
    for (const NodeField* pred : {&constant, &smooth, &random})
      for (const Interpolation how : {Interpolation::sinc, Interpolation::cubic}) {
        SCOPED_TRACE(std::string(isa_name(build)) + (how == Interpolation::sinc ? ", sinc" : ", cubic") +
                     (pred == &constant ? ", constant"
                      : pred == &smooth ? ", smooth"
                                        : ", random"));
        std::vector<float> da(a.size()), db(a.size());
        deform_pair(a, b, shape, *pred, da, db, how);
        std::size_t differ = 0;
        for (int z = 0; z < shape[2]; ++z)
          for (int y = 0; y < shape[1]; ++y)
            for (int x = 0; x < shape[0]; ++x) {
              const auto d = pred->at(x, y, z);
              const double hx = 0.5 * d[0], hy = 0.5 * d[1], hz = 0.5 * d[2];
              const float ea = how == Interpolation::sinc ? sample_sinc7(a, shape, x - hx, y - hy, z - hz)
                                                          : cubic(a, x - hx, y - hy, z - hz);
              const float eb = how == Interpolation::sinc ? sample_sinc7(b, shape, x + hx, y + hy, z + hz)
                                                          : cubic(b, x + hx, y + hy, z + hz);
              const std::size_t i = (std::size_t(z) * shape[1] + y) * shape[0] + x;
              differ += std::memcmp(&da[i], &ea, sizeof ea) != 0 || std::memcmp(&db[i], &eb, sizeof eb) != 0;
            }
        EXPECT_EQ(differ, 0u);
      }
  }
  use_isa(chosen);
}

TEST(Deform, MeanFloorSubtractsAMultipleOfTheMeanAndClipsAtZero) {
  const std::array<int, 3> shape{4, 3, 2};
  std::vector<float> in(24);
  for (std::size_t i = 0; i < in.size(); ++i) in[i] = float(i % 6);  // mean 2.5
  std::vector<float> out(in.size(), -1.f);
  EXPECT_FLOAT_EQ(subtract_mean_floor(in, shape, 1.2, out), 3.f);
  for (std::size_t i = 0; i < in.size(); ++i) EXPECT_FLOAT_EQ(out[i], std::max(0.f, in[i] - 3.f)) << i;
  EXPECT_FLOAT_EQ(subtract_mean_floor(in, shape, 0.0, out), 0.f);
  EXPECT_EQ(out, in);
  // In place, and the same bits at 1 and 2 threads on a volume that is split between them.
  const Grid3 g = cube(40);
  const Volume v = blobs(g, random_points(g, 300, 3));
  HugePageVector<float> one = v.data, two = v.data;
  {
    tbb::global_control c(tbb::global_control::max_allowed_parallelism, 1);
    subtract_mean_floor(one, g.shape, 4.0, one);
  }
  {
    tbb::global_control c(tbb::global_control::max_allowed_parallelism, 2);
    subtract_mean_floor(two, g.shape, 4.0, two);
  }
  EXPECT_EQ(std::memcmp(one.data(), two.data(), one.size() * sizeof(float)), 0);
  EXPECT_GT(std::count(one.begin(), one.end(), 0.f), std::ptrdiff_t(one.size() / 2));
}

// CorrelationSettings::depth_prefilter's kernel: K more [1 2 1] / 4 passes along z after the
// prefilter. A single bright voxel comes out as the prefilter's [1 2 1] / 4 across x and y and the
// binomial row of 2 (K + 1) along z; a volume with no depth structure is left as it is.
TEST(Deform, DepthPassesSmoothAlongDepthOnly) {
  const std::array<int, 3> shape{9, 9, 21};
  const std::size_t n = std::size_t(9) * 9 * 21;
  const auto idx = [&](int x, int y, int z) { return (std::size_t(z) * 9 + y) * 9 + x; };
  std::vector<float> spike(n, 0.f);
  spike[idx(4, 4, 10)] = 1.f;
  for (int k : {0, 2, 3}) {  // 3: an odd count ends in the scratch volume and is copied home
    std::vector<float> out(n, -1.f), scratch(n);
    binomial_smooth(spike, shape, out, scratch, k);
    const int order = 2 * (k + 1);
    double row = 1;  // binomial coefficient C(order, j), walked along j
    for (int j = 0; j <= order; ++j) {
      const int z = 10 - (k + 1) + j;
      const double along_z = row / std::pow(4.0, k + 1);
      EXPECT_NEAR(out[idx(4, 4, z)], 0.25 * along_z, 1e-7) << "k " << k << " z " << z;
      EXPECT_NEAR(out[idx(3, 4, z)], 0.125 * along_z, 1e-7) << "k " << k << " z " << z;
      EXPECT_NEAR(out[idx(3, 5, z)], 0.0625 * along_z, 1e-7) << "k " << k << " z " << z;
      row = row * (order - j) / (j + 1);
    }
    EXPECT_EQ(out[idx(4, 4, 10 - k - 2)], 0.f) << k;  // nothing beyond the kernel's reach
    EXPECT_EQ(out[idx(2, 4, 10)], 0.f) << k;          // nor laterally
  }
  // A volume that varies across x and y but not along z keeps its values through the depth passes
  // (the faces renormalise the kernel's inner taps).
  std::vector<float> columns(n);
  for (int z = 0; z < 21; ++z)
    for (int y = 0; y < 9; ++y)
      for (int x = 0; x < 9; ++x) columns[idx(x, y, z)] = float((x * 7 + y * 3) % 5);
  std::vector<float> plain(n), deep(n), scratch(n);
  binomial_smooth(columns, shape, plain, scratch, 0);
  binomial_smooth(columns, shape, deep, scratch, 4);
  for (std::size_t i = 0; i < n; ++i) EXPECT_NEAR(deep[i], plain[i], 1e-5) << i;
}

// correlate_star against the transform's correlation at the same seven shifts, for the paper's
// 16-wide windows and widths that leave a tail of single lanes (13, 9) or fill no vector (3), with a
// large common offset (the means must come out); every build this CPU runs gives the same bits.
TEST(DirectCorrelation, TheStarHasTheTransformsValuesAtItsShifts) {
  const Isa chosen = isa();
  const std::vector<Isa> builds = builds_to_test();
  const std::array<std::array<int, 3>, kStarShifts> shifts{
      {{0, 0, 0}, {-1, 0, 0}, {1, 0, 0}, {0, -1, 0}, {0, 1, 0}, {0, 0, -1}, {0, 0, 1}}};
  for (const std::array<int, 3> shape :
       {std::array<int, 3>{16, 16, 8}, {13, 10, 7}, {9, 4, 3}, {3, 3, 3}, {32, 8, 4}}) {
    SCOPED_TRACE("shape " + std::to_string(shape[0]) + "x" + std::to_string(shape[1]) + "x" + std::to_string(shape[2]));
    const std::size_t n = std::size_t(shape[0]) * shape[1] * shape[2];
    std::mt19937 rng(17);
    std::uniform_real_distribution<float> u(0, 1);
    std::vector<float> a(n), b(n);
    for (std::size_t i = 0; i < n; ++i) {
      a[i] = 50 + u(rng);
      b[i] = 20 + u(rng);
    }
    FftCorrelator corr(shape);
    auto& ws = corr.workspace();
    std::copy(a.begin(), a.end(), ws.window_a().begin());
    std::copy(b.begin(), b.end(), ws.window_b().begin());
    const std::span<const float> r = ws.correlate();
    const float largest =
        std::abs(*std::max_element(r.begin(), r.end(), [](float x, float y) { return std::abs(x) < std::abs(y); }));
    ASSERT_GT(largest, 0.f);
    std::vector<float> scratch;
    std::array<float, kStarShifts> first_build{};
    for (const Isa build : builds) {
      SCOPED_TRACE(isa_name(build));
      use_isa(build);
      const auto star = correlate_star(a, b, shape, scratch);
      for (int k = 0; k < kStarShifts; ++k) {
        std::size_t at = 0;
        for (int axis = 2; axis >= 0; --axis)
          at = at * std::size_t(shape[axis]) + std::size_t((shifts[k][axis] + shape[axis]) % shape[axis]);
        EXPECT_NEAR(star[k], r[at], 2e-5 * largest) << "shift " << k;
      }
      if (build == builds.front())
        first_build = star;
      else
        EXPECT_TRUE(testing_support::same_bits(star, first_build)) << "not the bits of the first build";
    }
  }
  use_isa(chosen);
  std::vector<float> scratch, w(16 * 16 * 2, 1.f);
  EXPECT_THROW(correlate_star(w, w, {16, 16, 2}, scratch), std::invalid_argument);
  EXPECT_THROW(correlate_star(w, w, {16, 16, 3}, scratch), std::invalid_argument);
}

// Bias and RMS per component of the valid vectors against a uniform displacement (voxels).
struct Errors {
  P3 bias{0, 0, 0}, rms{0, 0, 0};
  std::size_t valid = 0;
};
Errors errors_against(const CorrelationResult& r, const P3& truth_vox, const Grid3& g, int skip_border = 0) {
  Errors e;
  const auto& f = r.field;
  const std::array<const std::vector<float>*, 3> comp{&f.dx_mm, &f.dy_mm, &f.dz_mm};
  for (std::size_t n = 0; n < f.grid.count(); ++n) {
    if (!f.valid[n]) continue;
    const std::array<int, 3> i{int(n % f.grid.shape[0]), int(n / f.grid.shape[0] % f.grid.shape[1]),
                               int(n / (f.grid.shape[0] * f.grid.shape[1]))};
    bool border = false;
    for (int a = 0; a < 3; ++a) border |= i[a] < skip_border || i[a] >= f.grid.shape[a] - skip_border;
    if (border) continue;
    ++e.valid;
    for (int a = 0; a < 3; ++a) {
      const double err = (*comp[a])[n] / g.spacing_mm[a] - truth_vox[a];
      e.bias[a] += err;
      e.rms[a] += err * err;
    }
  }
  for (int a = 0; a < 3; ++a) {
    e.bias[a] /= double(e.valid);
    e.rms[a] = std::sqrt(e.rms[a] / double(e.valid));
  }
  return e;
}

// One line for a test's log: RMS and bias per component of two correlations of the same volumes.
void print_before_after(const char* what, const Errors& before, const Errors& after) {
  std::printf("%s: RMS %.4f %.4f %.4f -> %.4f %.4f %.4f voxel; bias %.4f %.4f %.4f -> %.4f %.4f %.4f\n", what,
              before.rms[0], before.rms[1], before.rms[2], after.rms[0], after.rms[1], after.rms[2], before.bias[0],
              before.bias[1], before.bias[2], after.bias[0], after.bias[1], after.bias[2]);
}

CorrelationSettings small_settings() {
  CorrelationSettings s;
  s.passes = {{{24, 24, 24}, 50}, {{16, 16, 16}, 50}, {{16, 16, 16}, 50}};
  s.dt_s = 1e-3;
  return s;
}

TEST(Multipass, UniformSubvoxelShiftsAreRecovered) {
  const Grid3 g = cube(64);
  const auto pa = sim::particles_around(g, 11);
  const Volume a = sim::render_exact_volume(g, pa);
  // The same passes, and with a depth margin of 4 on the middle one, as the default has one
  // before its final passes (compact particles: nothing to correct there, and nothing may get
  // worse).
  CorrelationSettings margins = small_settings();
  margins.passes[1].depth_margin = 4;
  for (const CorrelationSettings& settings : {small_settings(), margins}) {
    double worst_bias = 0, worst_rms = 0;
    for (int step = 0; step <= 10; ++step) {
      const double t = 0.1 * step;
      const P3 d{t, 1 - t, 0.5 * t};  // voxels
      const sim::UniformFlow flow({d[0] * 0.1, d[1] * 0.1, d[2] * 0.1});
      const Volume b = sim::render_exact_volume(g, sim::displace(pa, flow));
      const auto r = correlate_volumes(a, b, settings);
      EXPECT_EQ(errors_against(r, d, g).valid, r.field.grid.count());
      // Windows on the volume's faces lose partners of clipped particles; the bounds are for the
      // interior vectors (docs/benchmarks.md, "Uniform shifts", gives both).
      const Errors e = errors_against(r, d, g, 1);
      for (int a = 0; a < 3; ++a) {
        worst_bias = std::max(worst_bias, std::abs(e.bias[a]));
        worst_rms = std::max(worst_rms, e.rms[a]);
      }
    }
    std::printf("uniform shifts, depth margins %d: worst |bias| %.4f, worst RMS %.4f voxel\n",
                settings.passes[1].depth_margin, worst_bias, worst_rms);
    // Sub-voxel accuracy on compact particles, with and without the margin (the issue asks for
    // |bias| < 0.02 and RMS < 0.05 voxel; a margin on the final pass would break the RMS bound,
    // which is why the default's final pass has none).
    EXPECT_LT(worst_bias, 0.01) << "measured 0.0046 (0.0044 with the margin)";
    EXPECT_LT(worst_rms, 0.015) << "measured 0.0098 (0.0098 with the margin)";
  }
}

// A reconstruction's ghosts, in miniature: a faint haze that is the same in both exposures (here
// many dim particles that do not move) pulls the measured displacement toward zero. The
// intensity floor (CorrelationSettings::intensity_threshold_of_mean) takes most of that pull away.
TEST(Multipass, TheIntensityFloorRemovesAStationaryHazesPull) {
  const Grid3 g = cube(48);
  const auto pa = sim::particles_around(g, 21);
  const P3 d{0, 0, 1.5};  // voxels, along depth as the ghosts' pull is largest there
  const sim::UniformFlow flow({0, 0, d[2] * 0.1});
  Volume a = sim::render_exact_volume(g, pa);
  Volume b = sim::render_exact_volume(g, sim::displace(pa, flow));
  // Five times the particles' count at 0.15 of their intensity: as much light as the particles.
  std::vector<sim::Point3> haze_points;
  for (std::uint64_t seed : {31, 32, 33, 34, 35}) {
    const auto p = sim::particles_around(g, seed);
    haze_points.insert(haze_points.end(), p.begin(), p.end());
  }
  const Volume haze = sim::render_exact_volume(g, haze_points);
  for (std::size_t i = 0; i < a.data.size(); ++i) {
    a.data[i] += 0.15f * haze.data[i];
    b.data[i] += 0.15f * haze.data[i];
  }
  CorrelationSettings plain = small_settings(), floored = small_settings();
  floored.intensity_threshold_of_mean = 4;
  const Errors without = errors_against(correlate_volumes(a, b, plain), d, g, 1);
  const Errors with = errors_against(correlate_volumes(a, b, floored), d, g, 1);
  std::printf(
      "stationary haze, depth shift 1.5 voxel: bias %.3f without the floor, %.3f with 4x the mean; "
      "RMS %.3f, %.3f\n",
      without.bias[2], with.bias[2], without.rms[2], with.rms[2]);
  // The haze pulls the depth shift short; the floor takes most of that pull away.
  EXPECT_LT(without.bias[2], -0.1) << "measured -0.134";
  EXPECT_GT(with.bias[2], 0.4 * without.bias[2]) << "measured -0.038 against -0.134";
  EXPECT_LT(with.rms[2], 0.5 * without.rms[2]) << "measured 0.043 against 0.149";
}

// MART's light where lines of sight cross, in miniature: broad streaks along depth that stay where
// they are while compact particles move 1.5 voxel in depth. The plain cross-correlation's peak
// blends the two and the depth shift comes out short; robust phase correlation in the passes
// before the last (CorrelationSettings::spectral_whitening) evens out the spectrum, so the
// particles' finer detail sets the predictor.
TEST(Multipass, SpectralWhiteningTakesAwayTheStreaksPullOnTheDepthShift) {
  const Grid3 g = cube(48);
  const auto pa = sim::particles_around(g, 23);
  const P3 d{0, 0, 1.5};  // voxels
  const sim::UniformFlow flow({0, 0, d[2] * 0.1});
  Volume a = sim::render_exact_volume(g, pa);
  Volume b = sim::render_exact_volume(g, sim::displace(pa, flow));
  const Volume streaks = blobs(g, random_points(g, 400, 43), 4);  // 4 times as long as wide, not moving
  for (std::size_t i = 0; i < a.data.size(); ++i) {
    a.data[i] += 0.25f * streaks.data[i];
    b.data[i] += 0.25f * streaks.data[i];
  }
  CorrelationSettings plain = small_settings(), half = small_settings(), phase = small_settings();
  half.spectral_whitening = 0.5;
  phase.spectral_whitening = 1;
  for (CorrelationSettings* s : {&half, &phase}) s->whitened_peak_sigma_voxel = {1, 1, 1};
  const Errors e_plain = errors_against(correlate_volumes(a, b, plain), d, g, 1);
  const Errors e_half = errors_against(correlate_volumes(a, b, half), d, g, 1);
  const Errors e_phase = errors_against(correlate_volumes(a, b, phase), d, g, 1);
  std::printf(
      "still streaks, depth shift 1.5 voxel: bias %.3f plain, %.3f whitening 1/2, %.3f phase only; RMS %.3f, %.3f, "
      "%.3f; lateral RMS %.3f %.3f (1/2)\n",
      e_plain.bias[2], e_half.bias[2], e_phase.bias[2], e_plain.rms[2], e_half.rms[2], e_phase.rms[2], e_half.rms[0],
      e_half.rms[1]);
  // The streaks pull the plain depth shift short by a large part; the pull shrinks as the passes
  // before the last are whitened more, and the lateral components stay accurate.
  EXPECT_LT(e_plain.bias[2], -0.35) << "measured -0.442";
  EXPECT_GT(e_half.bias[2], 0.92 * e_plain.bias[2]) << "measured -0.372 against -0.442";
  EXPECT_GT(e_phase.bias[2], 0.75 * e_plain.bias[2]) << "measured -0.284 against -0.442";
  EXPECT_LT(std::max(e_half.rms[0], e_half.rms[1]), 0.05) << "measured 0.024, 0.023";
}

// The whitening weighs only the passes before the last: a single pass is the plain correlation, bit
// for bit, and a second pass after it moves the vectors.
TEST(Multipass, SpectralWhiteningLeavesTheLastPassPlain) {
  const Grid3 g = cube(48);
  const auto pa = sim::particles_around(g, 25);
  const sim::UniformFlow flow({0.03, -0.02, 0.05});
  const Volume a = sim::render_exact_volume(g, pa), b = sim::render_exact_volume(g, sim::displace(pa, flow));
  CorrelationSettings plain = small_settings();
  plain.passes = {{{16, 16, 16}, 50}};
  CorrelationSettings whitened = plain;
  whitened.spectral_whitening = 1;
  const VectorField one_plain = correlate_volumes(a, b, plain).field;
  const VectorField one_whitened = correlate_volumes(a, b, whitened).field;
  EXPECT_EQ(one_plain.dx_mm, one_whitened.dx_mm);
  EXPECT_EQ(one_plain.dy_mm, one_whitened.dy_mm);
  EXPECT_EQ(one_plain.dz_mm, one_whitened.dz_mm);
  plain.passes.insert(plain.passes.begin(), PassSettings{{24, 24, 24}, 50});
  whitened.passes = plain.passes;
  EXPECT_NE(correlate_volumes(a, b, plain).field.dz_mm, correlate_volumes(a, b, whitened).field.dz_mm);
}

// Reconstructed particles are streaks along depth (paper sec 6.2: about 4 times as long as wide).
// A window's depth faces cut them at the same place in both volumes, and the cut ends pull the
// depth shift toward zero; the second window reaching further in depth (PassSettings::
// depth_margin) removes that pull. The default's schedule, with and without its margins.
TEST(Multipass, ADepthMarginRemovesThePullOfStreaksCutByTheWindow) {
  const Grid3 g = cube(48);
  const auto at = random_points(g, 400, 41);
  std::vector<P3> moved = at;
  const P3 d{0, 0, 2.5};  // voxels
  for (P3& p : moved) p[2] += d[2];
  const Volume a = blobs(g, at, 4), b = blobs(g, moved, 4);  // streaks 4 times as long as wide
  CorrelationSettings with;              // the default passes, a margin of 4 on the first 16^3, 50 % pass
  with.passes[0].window = {24, 24, 24};  // the 48^3 volume holds 3 windows of 24^3 at 50 %
  CorrelationSettings without = with;
  for (PassSettings& p : without.passes) p.depth_margin = 0;
  ASSERT_EQ(with.passes[1].depth_margin, 4);
  const Errors e_with = errors_against(correlate_volumes(a, b, with), d, g, 1);
  const Errors e_without = errors_against(correlate_volumes(a, b, without), d, g, 1);
  std::printf(
      "streaks sigma_z 4, depth shift 2.5 voxels: bias %.3f without margins, %.3f with; RMS %.3f, %.3f; "
      "lateral RMS %.3f %.3f with\n",
      e_without.bias[2], e_with.bias[2], e_without.rms[2], e_with.rms[2], e_with.rms[0], e_with.rms[1]);
  // Without margins the depth shift comes out short by a large part of it; with the default's
  // margin the bias and the random error nearly vanish.
  EXPECT_LT(e_without.bias[2], -0.5) << "measured -0.727";
  EXPECT_LT(std::abs(e_with.bias[2]), 0.05) << "measured -0.010";
  EXPECT_LT(e_with.rms[2], 0.05) << "measured 0.018 (0.731 without margins)";
  EXPECT_LT(std::max(e_with.rms[0], e_with.rms[1]), 0.01) << "measured 0.003";
}

// A reconstruction's noise, in miniature: dim particles that differ between the exposures (as
// much light as the particles) add random error to a uniform shift. Smoothing the final field
// (CorrelationSettings::final_smoothing) lowers it and leaves the mean where it was.
TEST(Multipass, FinalSmoothingLowersTheRandomErrorOfAUniformShift) {
  const Grid3 g = cube(64);
  const auto pa = sim::particles_around(g, 51);
  const P3 d{0.3, -0.6, 1.2};  // voxels
  const sim::UniformFlow flow({d[0] * 0.1, d[1] * 0.1, d[2] * 0.1});
  Volume a = sim::render_exact_volume(g, pa);
  Volume b = sim::render_exact_volume(g, sim::displace(pa, flow));
  for (Volume* v : {&a, &b}) {
    std::vector<sim::Point3> noise_points;
    for (std::uint64_t k = 0; k < 4; ++k) {
      const auto p = sim::particles_around(g, (v == &a ? 60 : 70) + k);
      noise_points.insert(noise_points.end(), p.begin(), p.end());
    }
    const Volume noise = sim::render_exact_volume(g, noise_points);
    for (std::size_t i = 0; i < v->data.size(); ++i) v->data[i] += 0.25f * noise.data[i];
  }
  CorrelationSettings plain = small_settings(), smoothed = small_settings();
  smoothed.final_smoothing = 1;
  const Errors e0 = errors_against(correlate_volumes(a, b, plain), d, g, 1);
  const Errors e1 = errors_against(correlate_volumes(a, b, smoothed), d, g, 1);
  print_before_after("uniform shift with frame-to-frame noise, unsmoothed -> one final smoothing pass", e0, e1);
  // The random error falls below 0.7 of itself and the bias stays. (This final pass is 16^3 at
  // 50 %: neighbouring windows share less than at 75 %, so their errors are less alike and the
  // smoothing takes more of them than on the paper's ring.)
  for (int a = 0; a < 3; ++a) {
    EXPECT_LT(e1.rms[a], 0.7 * e0.rms[a]) << a << " (measured 0.0272 0.0280 0.0182 against 0.0501 0.0509 0.0441)";
    EXPECT_NEAR(e1.bias[a], e0.bias[a], 0.01) << a << " (measured moved by 0.002-0.003)";
  }
}

// A reconstruction in miniature: particles as streaks 4 times as long in depth as wide, and
// round fragments (sigma 1 voxel, twice as many, as much light in all) that differ between the
// exposures, as MART's ghosts and noise do. The depth prefilter (CorrelationSettings::
// depth_prefilter) takes out depth detail finer than any streak's, which only the fragments
// have, and with it random error in all three components, most in depth.
TEST(Multipass, DepthPrefilterLowersTheNoiseOfElongatedParticles) {
  const Grid3 g = cube(64);
  const auto at = random_points(g, 700, 61);
  std::vector<P3> moved = at;
  const P3 d{0.4, -0.7, 1.3};  // voxels
  for (P3& p : moved)
    for (int a = 0; a < 3; ++a) p[a] += d[a];
  Volume a = blobs(g, at, 4), b = blobs(g, moved, 4);
  for (Volume* v : {&a, &b}) {
    const Volume fragments = blobs(g, random_points(g, 1400, v == &a ? 62 : 63), 1);
    for (std::size_t i = 0; i < v->data.size(); ++i) v->data[i] += fragments.data[i];
  }
  CorrelationSettings plain = small_settings();
  plain.passes[1].depth_margin = 4;       // as core/piv's default: streaks cut by the window
  plain.intensity_threshold_of_mean = 1;  // and a floor, as for MART's haze
  CorrelationSettings deep = plain;
  deep.depth_prefilter = 4;
  const Errors e0 = errors_against(correlate_volumes(a, b, plain), d, g, 1);
  const Errors e4 = errors_against(correlate_volumes(a, b, deep), d, g, 1);
  print_before_after("streaks sigma_z 4 among fragments, no depth passes -> 4", e0, e4);
  // The random error falls in every component, most in depth, and no bias grows.
  EXPECT_LT(e4.rms[0], 0.97 * e0.rms[0]) << "measured 0.1190 against 0.1254";
  EXPECT_LT(e4.rms[1], 0.95 * e0.rms[1]) << "measured 0.1036 against 0.1124";
  EXPECT_LT(e4.rms[2], 0.92 * e0.rms[2]) << "measured 0.3533 against 0.4009";
  for (int k = 0; k < 3; ++k) EXPECT_LE(std::abs(e4.bias[k]), std::abs(e0.bias[k]) + 0.005) << k;
}

// A reconstruction's box faces cut the depth streaks as a window's faces do. With the slices
// beyond them as depth context (correlate_volumes' depth_context: no window there, but the margin
// and the deformation see them), the vectors at the faces keep the whole depth shift. The same
// nodes as the cropped volume's.
TEST(Multipass, DepthContextLetsTheFaceWindowsSeeTheCutStreaks) {
  const int context = 8;
  Grid3 full = cube(48);
  full.shape[2] = 48 + 2 * context;
  const auto at = random_points(full, 530, 43);
  std::vector<P3> moved = at;
  const P3 d{0, 0, 2.5};  // voxels
  for (P3& p : moved) p[2] += d[2];
  const Volume a = blobs(full, at, 4), b = blobs(full, moved, 4);  // streaks 4 times as long as wide
  // The box without the context slices, as core/process crops its guard.
  Grid3 box = full;
  box.shape[2] = 48;
  box.origin_mm[2] += context * full.spacing_mm[2];
  const auto crop = [&](const Volume& v) {
    Volume c(box);
    const std::size_t slice = std::size_t(box.shape[0]) * box.shape[1];
    std::copy_n(v.data.begin() + std::ptrdiff_t(context * slice), c.data.size(), c.data.begin());
    return c;
  };
  CorrelationSettings s;  // the default passes, the first one's windows fitted to the 48^3 box
  s.passes[0].window = {24, 24, 24};
  const auto cropped = correlate_volumes(crop(a), crop(b), s);
  const auto with_context = correlate_volumes(a, b, s, {}, context);
  ASSERT_EQ(cropped.field.grid, with_context.field.grid);
  // The node planes whose final windows touch the box's depth faces, and the rest.
  const auto face_bias = [&](const CorrelationResult& r, bool faces) {
    const Grid3& g = r.field.grid;
    double sum = 0;
    std::size_t n = 0;
    for (std::size_t i = 0; i < g.count(); ++i) {
      const int k = int(i / (std::size_t(g.shape[0]) * g.shape[1]));
      if ((k == 0 || k == g.shape[2] - 1) != faces || !r.field.valid[i]) continue;
      sum += r.field.dz_mm[i] / full.spacing_mm[2] - d[2];
      ++n;
    }
    return sum / double(n);
  };
  const double cut = face_bias(cropped, true), seen = face_bias(with_context, true);
  const double inner_cut = face_bias(cropped, false), inner_seen = face_bias(with_context, false);
  std::printf(
      "depth streaks, shift 2.5 voxels, bias at the box's depth faces: %.3f cropped, %.3f with %d slices "
      "of context; inside %.3f and %.3f\n",
      cut, seen, context, inner_cut, inner_seen);
  // Cropped, the face windows' depth shift comes out short (the default's depth margin already
  // takes most of the pull of the windows' own faces); with the context it does not.
  EXPECT_LT(cut, -0.04) << "measured -0.068";
  EXPECT_LT(std::abs(seen), 0.02) << "measured 0.000";
  EXPECT_LT(std::abs(inner_seen), 0.02) << "measured 0.000";

  EXPECT_THROW(correlate_volumes(a, b, s, {}, -1), InputError);
  EXPECT_THROW(correlate_volumes(a, b, s, {}, 32), InputError);  // half the depth
  EXPECT_THROW(correlate_volumes(a, b, s, {}, 21), InputError);  // 64 - 42 = 22 slices: no 24-deep window
}

TEST(Multipass, SameBitsAtOneAndTwoThreads) {
  const Grid3 g = cube(48);
  const auto pa = sim::particles_around(g, 5);
  const sim::LinearShear shear({0.02, 0, 0}, 1, 0.0);
  const Volume a = sim::render_exact_volume(g, pa);
  const Volume b = sim::render_exact_volume(g, sim::displace(pa, shear));
  CorrelationSettings s = small_settings();
  s.passes[1].depth_margin = 4;  // both ways of filling the windows
  s.final_smoothing = 2;         // and 4 slices of depth context below
  s.depth_prefilter = 3;
  CorrelationResult r1, r2;
  {
    tbb::global_control one(tbb::global_control::max_allowed_parallelism, 1);
    r1 = correlate_volumes(a, b, s, {}, 4);
  }
  {
    tbb::global_control two(tbb::global_control::max_allowed_parallelism, 2);
    r2 = correlate_volumes(a, b, s, {}, 4);
  }
  ASSERT_EQ(r1.field.grid, r2.field.grid);
  const std::size_t bytes = r1.field.dx_mm.size() * sizeof(float);
  EXPECT_EQ(std::memcmp(r1.field.dx_mm.data(), r2.field.dx_mm.data(), bytes), 0);
  EXPECT_EQ(std::memcmp(r1.field.dy_mm.data(), r2.field.dy_mm.data(), bytes), 0);
  EXPECT_EQ(std::memcmp(r1.field.dz_mm.data(), r2.field.dz_mm.data(), bytes), 0);
  EXPECT_EQ(std::memcmp(r1.field.peak_ratio.data(), r2.field.peak_ratio.data(), bytes), 0);
  EXPECT_EQ(r1.field.valid, r2.field.valid);
  EXPECT_EQ(r1.flags, r2.flags);
}

// The final pass's peak looked for at the predictor first (FinalPeakSearch::near_predictor), on
// a sheared pair with noise in both volumes: most peaks are taken there without the transform,
// their vectors are the transform's to float rounding (the same seven values, the same fits), a
// peak there that the median test rejects is searched over all shifts (so every rejected vector
// has a peak ratio), the result has the same bits at one and two threads, and a final pass with a
// depth margin is refused.
TEST(Multipass, APeakSearchAtThePredictorKeepsTheTransformsVectors) {
  const Grid3 g = cube(48);
  const auto pa = sim::particles_around(g, 5);
  const sim::LinearShear shear({0.03, 0, 0}, 1, 0.0);
  Volume a = sim::render_exact_volume(g, pa), b = sim::render_exact_volume(g, sim::displace(pa, shear));
  std::mt19937 rng(8);
  const float peak = *std::max_element(a.data.begin(), a.data.end());
  std::uniform_real_distribution<float> noise(0, 0.6f * peak);
  for (Volume* v : {&a, &b})
    for (float& x : v->data) x += noise(rng) * noise(rng) / peak;
  CorrelationSettings all = small_settings();
  all.passes.back().overlap_percent = 75;
  CorrelationSettings near = all;
  near.final_peak_search = FinalPeakSearch::near_predictor;
  const CorrelationResult whole = correlate_volumes(a, b, all);
  CorrelationResult first, second;
  {
    tbb::global_control one(tbb::global_control::max_allowed_parallelism, 1);
    first = correlate_volumes(a, b, near);
  }
  {
    tbb::global_control two(tbb::global_control::max_allowed_parallelism, 2);
    second = correlate_volumes(a, b, near);
  }
  const PassReport& report = first.passes.back();
  const std::size_t windows = report.windows;
  std::printf(
      "peaks at the predictor: %zu of %zu windows, %zu rejected and searched again; outliers %zu (all "
      "shifts: %zu)\n",
      report.near_peaks, windows, report.near_rejected, report.validation.outliers,
      whole.passes.back().validation.outliers);
  EXPECT_GT(report.near_peaks, windows * 9 / 10);
  EXPECT_GT(report.near_rejected, 0u) << "the noise should make the median test reject some";
  EXPECT_EQ(whole.passes.back().near_peaks, 0u);
  std::size_t at_predictor = 0, differ = 0;
  double worst = 0;
  constexpr std::uint8_t rejected = flag_second_peak | flag_third_peak | flag_interpolated | flag_unresolved;
  for (std::size_t n = 0; n < first.field.grid.count(); ++n) {
    const bool found_near = std::isnan(first.field.peak_ratio[n]);
    at_predictor += found_near;
    if (found_near) {
      EXPECT_FALSE(first.flags[n] & rejected) << "node " << n;
    }
    if (!first.field.valid[n] || !whole.field.valid[n]) {
      differ += first.field.valid[n] != whole.field.valid[n];
      continue;
    }
    const double d = std::max({std::abs(first.field.dx_mm[n] - whole.field.dx_mm[n]),
                               std::abs(first.field.dy_mm[n] - whole.field.dy_mm[n]),
                               std::abs(first.field.dz_mm[n] - whole.field.dz_mm[n])}) /
                     g.spacing_mm[0];
    if (d > 1e-3)
      ++differ;
    else
      worst = std::max(worst, d);
  }
  EXPECT_EQ(at_predictor, report.near_peaks);
  std::printf("vectors differing from the transform's by > 1e-3 voxel: %zu; the rest within %.2g voxel\n", differ,
              worst);
  EXPECT_LT(worst, 1e-4);
  EXPECT_LT(differ, windows / 100 + 1);
  EXPECT_TRUE(testing_support::same_bits(first.field.dx_mm, second.field.dx_mm));
  EXPECT_TRUE(testing_support::same_bits(first.field.dy_mm, second.field.dy_mm));
  EXPECT_TRUE(testing_support::same_bits(first.field.dz_mm, second.field.dz_mm));
  EXPECT_TRUE(testing_support::same_bits(first.field.peak_ratio, second.field.peak_ratio));
  EXPECT_EQ(first.flags, second.flags);
  CorrelationSettings margin = near;
  margin.passes.back().depth_margin = 2;
  EXPECT_THROW(correlate_volumes(a, b, margin), InputError);
}

// A kept workspace changes no bit: a 48^3 pair, a smaller 32^3 pair (after a larger one), then the
// first again, each with the floor, prefilter and smoothing that use every buffer, against the same
// correlation without a workspace. One correlation at a time: starting a second one in the same
// workspace from inside the first is a caller's bug (std::logic_error), and leaves it usable.
TEST(Multipass, AKeptWorkspaceGivesTheBitsOfNone) {
  CorrelationSettings s = small_settings();
  s.intensity_threshold_of_mean = 2;
  s.depth_prefilter = 2;
  s.final_smoothing = 1;
  const sim::LinearShear shear({0.02, 0, 0}, 1, 0.0);
  const auto pair = [&](int n, unsigned seed) {
    const Grid3 g = cube(n);
    const auto p = sim::particles_around(g, seed);
    return std::pair{sim::render_exact_volume(g, p), sim::render_exact_volume(g, sim::displace(p, shear))};
  };
  const auto large = pair(48, 5), small = pair(32, 9);
  CorrelationWorkspace workspace;
  for (const auto* v : {&large, &small, &large}) {
    const CorrelationResult kept = correlate_volumes(v->first, v->second, s, {}, 0, &workspace);
    const CorrelationResult alone = correlate_volumes(v->first, v->second, s);
    EXPECT_EQ(kept.field.dx_mm, alone.field.dx_mm);
    EXPECT_EQ(kept.field.dy_mm, alone.field.dy_mm);
    EXPECT_EQ(kept.field.dz_mm, alone.field.dz_mm);
    EXPECT_EQ(kept.field.valid, alone.field.valid);
    EXPECT_EQ(kept.flags, alone.flags);
  }
  EXPECT_GE(workspace.bytes(), 4 * large.first.data.size() * sizeof(float));
  EXPECT_THROW(correlate_volumes(
                   large.first, large.second, s,
                   [&](const PassReport&) { correlate_volumes(small.first, small.second, s, {}, 0, &workspace); }, 0,
                   &workspace),
               std::logic_error);
  EXPECT_EQ(correlate_volumes(small.first, small.second, s, {}, 0, &workspace).field.dx_mm,
            correlate_volumes(small.first, small.second, s).field.dx_mm);
}

// The paper's ring vortex (8 mm ring, r_c 40 voxels, v_rc 8 voxels, 0.1 mm voxels) on a region
// cropped around it, 128x96x96 voxels: the default passes with deformation against one pass with
// the same final windows (16^3, 75 % overlap), and against three passes with the residual added
// to the predictor's window mean and no smoothing between passes.
TEST(Multipass, WindowDeformationReducesTheRingVortexError) {
  Grid3 g;
  g.shape = {128, 96, 96};
  g.spacing_mm = {0.1, 0.1, 0.1};
  for (int a = 0; a < 3; ++a) g.origin_mm[a] = -0.5 * (g.shape[a] - 1) * g.spacing_mm[a];
  const sim::RingVortexFlow::Parameters p;  // the paper's
  const sim::RingVortexFlow flow(p);
  const auto pa = sim::particles_around(g, 7);
  const Volume a = sim::render_exact_volume(g, pa);
  const Volume b = sim::render_exact_volume(g, sim::displace(pa, flow));
  CorrelationSettings single;
  single.passes = {{{16, 16, 16}, 75}};
  CorrelationSettings previous;
  previous.passes = {{{32, 32, 32}, 50}, {{16, 16, 16}, 50}, {{16, 16, 16}, 75}};
  previous.predictor = PredictorBase::window_mean;
  previous.predictor_smoothing = 0;
  const CorrelationSettings multi;  // the defaults
  const auto r1 = correlate_volumes(a, b, single);
  const auto r0 = correlate_volumes(a, b, previous);
  const auto r3 = correlate_volumes(a, b, multi);
  ASSERT_EQ(r1.field.grid, r3.field.grid);
  // RMS per component against the flow, truth where the particle sat halfway through its move.
  const P3 e1 = sim::field_errors(r1.field, flow, 0.1).rms, e0 = sim::field_errors(r0.field, flow, 0.1).rms,
           e3 = sim::field_errors(r3.field, flow, 0.1).rms;
  // Away from the axis band (the windows reaching the ring's axis, where the exact u and w jump).
  const auto off_band = [&](const sim::Point3& x) { return !sim::in_ring_axis_band(flow, x, 0.8); };
  const P3 o3 = sim::field_errors(r3.field, flow, 0.1, 1, 0, off_band).rms;
  std::printf(
      "ring vortex RMS (voxels) single pass %.3f %.3f %.3f, previous default %.3f %.3f %.3f, default "
      "%.3f %.3f %.3f (off the axis band %.3f %.3f %.3f)\n",
      e1[0], e1[1], e1[2], e0[0], e0[1], e0[2], e3[0], e3[1], e3[2], o3[0], o3[1], o3[2]);
  // The default beats a single pass by about 3x and the three-pass window-mean schedule by 20 %
  // in every component (the crop cuts the cores: many windows here sit near its faces).
  for (int c = 0; c < 3; ++c) EXPECT_LT(e3[c], 0.35 * e1[c]) << c << " (measured 0.224 0.170 0.202; 1.028 0.706 0.729)";
  for (int c = 0; c < 3; ++c)
    EXPECT_LT(e3[c], 0.8 * e0[c]) << c << " (measured 0.224 0.170 0.202 against 0.34 0.30 0.32)";
  for (int c = 0; c < 3; ++c) EXPECT_LT(e3[c], 0.27) << c;
  for (int c = 0; c < 3; ++c) EXPECT_LT(o3[c], 0.2) << c << " (measured 0.123 0.171 0.110)";
}

TEST(Multipass, EmptyWindowsAreSkippedAndInvalid) {
  const Grid3 g = cube(48);
  std::vector<P3> pa;
  for (const P3& p : random_points(g, 400, 9))
    if (p[0] < 20) pa.push_back(p);  // particles only in the left part
  std::vector<P3> pb = pa;
  for (auto& p : pb) p[1] += 0.4;
  CorrelationSettings s;
  s.passes = {{{16, 16, 16}, 0}};
  const auto r = correlate_volumes(blobs(g, pa), blobs(g, pb), s);
  ASSERT_EQ(r.field.grid.shape[0], 3);
  for (std::size_t n = 0; n < r.field.grid.count(); ++n) {
    const bool right = n % 3 == 2;  // windows x 32..47: no particle within reach
    EXPECT_EQ(bool(r.flags[n] & flag_no_signal), right) << n;
    EXPECT_EQ(r.field.valid[n], right ? 0 : 1) << n;
  }
  EXPECT_EQ(r.passes[0].no_signal, 9u);
}

// A window whose voxels hold only numerical dust (values a millionth of the peak and less, what
// interpolation leaves at float rounding) has no particle signal either: no vector, no sigma. Faint
// particles, a thousandth of the others, still have one.
TEST(Multipass, WindowsOfNumericalDustAreNoSignalButFaintParticlesAreSignal) {
  const Grid3 g = cube(48);
  std::vector<P3> pa, faint;
  for (const P3& p : random_points(g, 400, 9)) (p[0] < 20 ? pa : faint).push_back(p);
  faint.erase(std::remove_if(faint.begin(), faint.end(), [](const P3& p) { return p[0] < 36; }), faint.end());
  const auto moved = [](std::vector<P3> p) {
    for (auto& q : p) q[1] += 0.4;
    return p;
  };
  Volume a = blobs(g, pa), b = blobs(g, moved(pa));
  // Dust in the right third (x 32..47) of both: scattered voxels at 1e-9 .. 1e-6 of the peak.
  std::mt19937 rng(4);
  std::uniform_real_distribution<float> level(1e-9f, 1e-6f);
  for (Volume* v : {&a, &b}) {
    const float peak = *std::max_element(v->data.begin(), v->data.end());
    for (int i = 0; i < 300; ++i) {
      const int x = 32 + int(rng() % 16), y = int(rng() % 48), z = int(rng() % 48);
      v->at(x, y, z) = level(rng) * peak;
    }
  }
  CorrelationSettings s;
  s.passes = {{{16, 16, 16}, 0}};
  s.uncertainty = true;
  const auto dusty = correlate_volumes(a, b, s);
  ASSERT_EQ(dusty.field.grid.shape[0], 3);
  for (std::size_t n = 0; n < dusty.field.grid.count(); ++n) {
    const bool right = n % 3 == 2;
    EXPECT_EQ(bool(dusty.flags[n] & flag_no_signal), right) << n;
    EXPECT_EQ(dusty.field.valid[n], right ? 0 : 1) << n;
    EXPECT_EQ(std::isnan(dusty.field.sigma_dx_mm[n]), right) << n;
  }
  EXPECT_EQ(dusty.passes[0].no_signal, 9u);

  // The same right third with particles instead, a thousandth as bright as the others or as bright:
  // signal both times, and the same vectors there.
  const auto with_right = [&](float brightness) {
    Volume fa = blobs(g, pa), fb = blobs(g, moved(pa));
    const Volume ga = blobs(g, faint), gb = blobs(g, moved(faint));
    for (std::size_t q = 0; q < fa.data.size(); ++q) {
      fa.data[q] += brightness * ga.data[q];
      fb.data[q] += brightness * gb.data[q];
    }
    return correlate_volumes(fa, fb, s);
  };
  const auto dim = with_right(1e-3f), bright = with_right(1.f);
  EXPECT_EQ(dim.passes[0].no_signal, 0u);
  for (std::size_t n = 2; n < dim.field.grid.count(); n += 3) {
    ASSERT_TRUE(dim.field.valid[n] && bright.field.valid[n]) << n;
    EXPECT_NEAR(dim.field.dy_mm[n], bright.field.dy_mm[n], 1e-4) << n;
  }
}

TEST(Multipass, DifferentGridsAndNonFiniteVoxelsAreRefused) {
  const Volume a(cube(32)), b(cube(33));
  EXPECT_THROW(correlate_volumes(a, b, small_settings()), InputError);
  Volume c(cube(32)), d(cube(32));
  d.data[5] = NAN;
  EXPECT_THROW(correlate_volumes(c, d, small_settings()), InputError);
  CorrelationSettings big;
  big.passes = {{{48, 16, 16}, 50}};
  EXPECT_THROW(correlate_volumes(c, c, big), InputError);
}

// The per-vector uncertainty (correlation statistics, uncertainty.hpp) against the true errors of a
// uniform shift among dim particles that differ between the exposures (random error, as a
// reconstruction's noise gives): the RMS of the predicted sigma against the RMS error, per
// component and per third of the depth, and the share of errors within +-1 and +-2 sigma. The
// vectors are the same bits with the uncertainty off.
TEST(Uncertainty, PredictsTheRandomErrorOfANoisyUniformShift) {
  const Grid3 g = cube(64);
  const auto pa = sim::particles_around(g, 51);
  const sim::UniformFlow flow({0.03, -0.06, 0.12});
  Volume a = sim::render_exact_volume(g, pa), b = sim::render_exact_volume(g, sim::displace(pa, flow));
  for (Volume* v : {&a, &b}) {
    std::vector<sim::Point3> noise_points;
    for (std::uint64_t k = 0; k < 4; ++k) {
      const auto p = sim::particles_around(g, (v == &a ? 60 : 70) + k);
      noise_points.insert(noise_points.end(), p.begin(), p.end());
    }
    const Volume noise = sim::render_exact_volume(g, noise_points);
    for (std::size_t i = 0; i < v->data.size(); ++i) v->data[i] += 0.25f * noise.data[i];
  }
  CorrelationSettings centre, window_mean, off;  // core/piv's default passes
  window_mean.predictor = PredictorBase::window_mean;
  off.uncertainty = false;
  const CorrelationResult r = correlate_volumes(a, b, centre);
  const CorrelationResult r_off = correlate_volumes(a, b, off);
  EXPECT_EQ(r.field.dx_mm, r_off.field.dx_mm);
  EXPECT_EQ(r.field.dy_mm, r_off.field.dy_mm);
  EXPECT_EQ(r.field.dz_mm, r_off.field.dz_mm);
  EXPECT_TRUE(r_off.field.sigma_dx_mm.empty());
  ASSERT_EQ(r.field.sigma_dz_mm.size(), r.field.grid.count());
  const double depth = (g.shape[2] - 1) * 0.1, z0 = g.origin_mm[2];
  for (const bool at_centre : {true, false}) {
    const CorrelationResult measured = at_centre ? r : correlate_volumes(a, b, window_mean);
    const VectorField& f = measured.field;
    const char* predictor = at_centre ? "centre" : "window_mean";
    for (int band = 0; band < 4; ++band) {
      const auto in_band = [&](const sim::Point3& x) {
        return band == 3 || std::min(2, int(3 * (x[2] - z0) / depth)) == band;
      };
      const sim::UncertaintyCheck c = sim::uncertainty_check(f, flow, 0.1, 1, 1, in_band);
      ASSERT_GT(c.compared, 300u) << band;
      for (int k = 0; k < 3; ++k) {
        const double ratio = c.rms_sigma[k] / c.rms_error[k];
        std::printf(
            "uncertainty, %s predictor, band %d, %c: RMS error %.4f, RMS sigma %.4f (%.3f), within 1 sigma "
            "%.3f, 2 sigma %.3f\n",
            predictor, band, "uvw"[k], c.rms_error[k], c.rms_sigma[k], ratio, c.within_1[k], c.within_2[k]);
        // The issue asks for the predicted RMS within 30 % of the measured. The centre predictor
        // (the default) adds its own interpolated error, which the final pass's correlation does
        // not see: sigma falls 15-25 % short over the volume (docs/accuracy.md), less with the
        // window-mean predictor. A third of the depth holds ~440 vectors: its figures scatter more.
        const std::string what = std::string(predictor) + " band " + std::to_string(band) + " " + "uvw"[k];
        EXPECT_GT(ratio, band == 3 ? (at_centre ? 0.7 : 0.78) : 0.6) << what << ": measured " << ratio;
        EXPECT_LT(ratio, 1.2) << what << ": measured " << ratio;
        EXPECT_GT(c.within_1[k], 0.38) << what << ": measured " << c.within_1[k];
        EXPECT_GT(c.within_2[k], 0.72) << what << ": measured " << c.within_2[k];
        EXPECT_LT(c.within_1[k], 0.8) << "measured " << c.within_1[k];
      }
    }
  }
}

// Two windows that match voxel for voxel have no asymmetry to spread: sigma 0; noise in one of
// them gives each axis a positive sigma, more for more noise.
TEST(Uncertainty, MatchingWindowsHaveNoneAndNoiseGivesSome) {
  const Grid3 g = cube(24);
  const Volume a = blobs(g, random_points(g, 60, 3));
  UncertaintyScratch scratch;
  const auto none =
      correlation_statistics_sigma(a.data, a.data, g.shape, {4, 4, 4}, {16, 16, 16}, 0, {0, 0, 0}, scratch);
  for (int k = 0; k < 3; ++k) EXPECT_EQ(none[k], 0.f) << k;
  std::array<float, 3> previous{0, 0, 0};
  for (float level : {0.02f, 0.1f}) {
    Volume b = a;
    std::mt19937 rng(5);
    std::normal_distribution<float> noise(0, level);
    for (float& v : b.data) v += noise(rng);
    const auto s =
        correlation_statistics_sigma(a.data, b.data, g.shape, {4, 4, 4}, {16, 16, 16}, 0, {0, 0, 0}, scratch);
    for (int k = 0; k < 3; ++k) {
      EXPECT_GT(s[k], previous[k]) << "noise " << level << " axis " << k;
      EXPECT_LT(s[k], 0.5f) << "noise " << level << " axis " << k;
    }
    previous = s;
  }
}

// The fast sums give what the method's definition gives, written out voxel by voxel (uncertainty.hpp):
// cyclic correlation sums of the mean-subtracted windows, each axis's asymmetry dC'(x), and its
// spread over a box clipped at the window's faces; windows with and without a depth margin, shifted
// peaks and a window that is not a cube.
TEST(Uncertainty, FastSumsMatchTheDefinitionVoxelByVoxel) {
  Grid3 g;
  g.shape = {30, 28, 32};
  g.spacing_mm = {0.1, 0.1, 0.1};
  const std::vector<P3> points = random_points(g, 90, 7);
  const Volume a = blobs(g, points, 2);
  std::mt19937 rng(9);
  std::normal_distribution<float> noise(0, 0.05f);
  struct Case {
    std::array<int, 3> origin, window;
    int margin;
    std::array<int, 3> shift;
  };
  // One thread's scratch kept from case to case, as vector_uncertainty keeps it from window to
  // window: the cases' windows, margins and radii differ, so a buffer's layout changes under it.
  UncertaintyScratch kept;
  for (const Case& c : {Case{{4, 4, 4}, {16, 16, 16}, 0, {0, 0, 0}}, Case{{6, 5, 8}, {16, 16, 16}, 3, {1, -2, 1}},
                        Case{{2, 8, 2}, {12, 16, 8}, 2, {-3, 0, 2}}, Case{{9, 3, 0}, {8, 12, 16}, 4, {0, 1, -1}}}) {
    // b(x + shift) = a(x), and noise.
    std::vector<P3> moved = points;
    for (P3& q : moved)
      for (int e = 0; e < 3; ++e) q[e] += c.shift[e];
    Volume b = blobs(g, moved, 2);
    for (float& v : b.data) v += noise(rng);
    const std::array<int, 3> n{c.window[0], c.window[1], c.window[2] + 2 * c.margin};
    const auto at = [&](int x, int y, int z) { return (std::size_t(z) * n[1] + y) * n[0] + x; };
    std::vector<double> wa(std::size_t(n[0]) * n[1] * n[2]), wb(wa.size());
    double sum_a = 0, sum_b = 0;
    for (int z = 0; z < n[2]; ++z)
      for (int y = 0; y < n[1]; ++y)
        for (int x = 0; x < n[0]; ++x) {
          const int vz = c.origin[2] - c.margin + z;
          const bool in_volume = vz >= 0 && vz < g.shape[2], in_a = z >= c.margin && z < c.margin + c.window[2];
          const int vx = c.origin[0] + x, vy = c.origin[1] + y;
          wa[at(x, y, z)] = in_a ? a.at(vx, vy, vz) : 0;
          wb[at(x, y, z)] = in_volume ? b.at(vx, vy, vz) : 0;
          sum_a += wa[at(x, y, z)];
          sum_b += wb[at(x, y, z)];
        }
    const double mean_a = sum_a / (double(c.window[0]) * c.window[1] * c.window[2]), mean_b = sum_b / double(wb.size());
    for (int z = c.margin; z < c.margin + c.window[2]; ++z)
      for (int y = 0; y < n[1]; ++y)
        for (int x = 0; x < n[0]; ++x) wa[at(x, y, z)] -= mean_a;
    for (double& v : wb) v -= mean_b;
    const auto cyc = [&](int i, int k) { return ((i % n[k]) + n[k]) % n[k]; };
    // a(x) b(x + s) and the asymmetry along one axis, cyclic.
    const auto term = [&](int x, int y, int z, std::array<int, 3> s) {
      return wa[at(x, y, z)] * wb[at(cyc(x + s[0], 0), cyc(y + s[1], 1), cyc(z + s[2], 2))];
    };
    double c0 = 0;
    std::array<double, 3> plus{}, minus{};
    std::array<std::vector<double>, 3> d;
    for (int e = 0; e < 3; ++e) d[e].resize(wa.size());
    for (int z = 0; z < n[2]; ++z)
      for (int y = 0; y < n[1]; ++y)
        for (int x = 0; x < n[0]; ++x) {
          c0 += term(x, y, z, c.shift);
          for (int e = 0; e < 3; ++e) {
            std::array<int, 3> up = c.shift, down = c.shift, x_e{x, y, z};
            ++up[e];
            --down[e];
            plus[e] += term(x, y, z, up);
            minus[e] += term(x, y, z, down);
            x_e[e] = cyc(x_e[e] + 1, e);
            d[e][at(x, y, z)] =
                term(x, y, z, up) - wa[at(x_e[0], x_e[1], x_e[2])] *
                                        wb[at(cyc(x + c.shift[0], 0), cyc(y + c.shift[1], 1), cyc(z + c.shift[2], 2))];
          }
        }
    std::array<int, 3> radius{1, 1, 1};
    for (int e = 0; e < 3; ++e) {
      const double curvature = std::log(plus[e]) - 2 * std::log(c0) + std::log(minus[e]);
      ASSERT_LT(curvature, 0) << "the case has a peak";
      radius[e] = std::clamp(int(std::lround(2 * std::sqrt(-1 / curvature))), 1, std::max(1, c.window[e] / 4));
    }
    UncertaintyScratch scratch;
    const auto fast =
        correlation_statistics_sigma(a.data, b.data, g.shape, c.origin, c.window, c.margin, c.shift, scratch);
    const auto reused =
        correlation_statistics_sigma(a.data, b.data, g.shape, c.origin, c.window, c.margin, c.shift, kept);
    EXPECT_TRUE(testing_support::same_bits(reused, fast)) << "a kept scratch changed sigma";
    for (int e = 0; e < 3; ++e) {
      const double m = (plus[e] - minus[e]) / double(wa.size());
      double spread_sq = 0;
      for (int z = 0; z < n[2]; ++z)
        for (int y = 0; y < n[1]; ++y)
          for (int x = 0; x < n[0]; ++x) {
            double near = 0;
            for (int qz = std::max(0, z - radius[2]); qz <= std::min(n[2] - 1, z + radius[2]); ++qz)
              for (int qy = std::max(0, y - radius[1]); qy <= std::min(n[1] - 1, y + radius[1]); ++qy)
                for (int qx = std::max(0, x - radius[0]); qx <= std::min(n[0] - 1, x + radius[0]); ++qx)
                  near += d[e][at(qx, qy, qz)] - m;
            spread_sq += (d[e][at(x, y, z)] - m) * near;
          }
      const double spread = std::sqrt(std::max(0.0, spread_sq));
      const double cp = 0.5 * (plus[e] + minus[e]) + 0.5 * spread, cm = 0.5 * (plus[e] + minus[e]) - 0.5 * spread;
      ASSERT_GT(cm, 0) << "the case stays on the Gaussian fit";
      const double expected = (std::log(cp) - std::log(cm)) / (4 * std::log(c0) - 2 * std::log(cp) - 2 * std::log(cm));
      EXPECT_GT(expected, 1e-4) << "axis " << e;
      EXPECT_NEAR(fast[e], expected, 1e-3 * expected)
          << "axis " << e << ", window at " << c.origin[0] << " " << c.origin[1] << " " << c.origin[2];
    }
  }
}

// How a field's sigma at uncertainty_stride 2 (`second`) stands against every node's own
// (`every`, the same windows): nodes whose indices are all multiples of 2 or the last, computed
// (their bits checked); nodes beside one without an estimate, computed from their own windows
// (bits checked); interpolated nodes, checked to be the mean of their bracketing nodes (stride
// 2's trilinear weights); and the rest, with their own bits, whose peak was at another integer
// shift than a bracketing node's.
struct StrideCounts {
  int computed = 0, beside_none = 0, other_shift = 0, interpolated = 0;
  double rms_log_ratio = 0;  // interpolated over own sigma, where the own one is positive
};
StrideCounts compare_strides(const VectorField& every, const VectorField& second) {
  StrideCounts counts;
  const std::array<int, 3> n = every.grid.shape;
  const auto at = [&](int i, int j, int k) {
    return std::size_t(i) + std::size_t(n[0]) * (std::size_t(j) + std::size_t(n[1]) * std::size_t(k));
  };
  const auto computed = [&](int i, int axis) { return i % 2 == 0 || i == n[axis] - 1; };
  const std::array<const std::vector<float>*, 3> s1{&every.sigma_dx_mm, &every.sigma_dy_mm, &every.sigma_dz_mm},
      s2{&second.sigma_dx_mm, &second.sigma_dy_mm, &second.sigma_dz_mm};
  double log_ratio_sq = 0;
  int ratios = 0;
  for (int k = 0; k < n[2]; ++k)
    for (int j = 0; j < n[1]; ++j)
      for (int i = 0; i < n[0]; ++i) {
        const std::size_t node = at(i, j, k);
        const auto same = [&] {
          for (int c = 0; c < 3; ++c)
            if (std::bit_cast<std::uint32_t>((*s1[c])[node]) != std::bit_cast<std::uint32_t>((*s2[c])[node]))
              return false;
          return true;
        };
        if (computed(i, 0) && computed(j, 1) && computed(k, 2)) {
          EXPECT_TRUE(same()) << "computed node " << i << " " << j << " " << k;
          ++counts.computed;
          continue;
        }
        if (std::isnan((*s1[0])[node])) continue;
        // The mean of the bracketing nodes per component, and whether each has an estimate.
        std::array<double, 3> mean{0, 0, 0};
        bool whole = true;
        const int ijk[3] = {i, j, k};
        for (int c = 0; c < 8; ++c) {
          int corner[3];
          for (int a = 0; a < 3; ++a) {
            const int low = ijk[a] - ijk[a] % 2;
            corner[a] = computed(ijk[a], a) ? ijk[a] : ((c >> a) & 1) ? std::min(low + 2, n[a] - 1) : low;
          }
          const std::size_t q = at(corner[0], corner[1], corner[2]);
          for (int comp = 0; comp < 3; ++comp) {
            whole = whole && std::isfinite((*s1[comp])[q]);
            mean[comp] += (*s1[comp])[q] / 8.0;
          }
        }
        if (!whole) {
          EXPECT_TRUE(same()) << "beside a node without an estimate: " << i << " " << j << " " << k;
          ++counts.beside_none;
          continue;
        }
        if (same()) {
          ++counts.other_shift;
          continue;
        }
        ++counts.interpolated;
        for (int comp = 0; comp < 3; ++comp) {
          const float v = (*s2[comp])[node];
          EXPECT_NEAR(v, mean[comp], 1e-5 * mean[comp]) << i << " " << j << " " << k << " component " << comp;
          if ((*s1[comp])[node] > 0) {  // 0: its own windows' asymmetry has no spread
            log_ratio_sq += std::pow(std::log(v / (*s1[comp])[node]), 2);
            ++ratios;
          }
        }
      }
  counts.rms_log_ratio = std::sqrt(log_ratio_sq / std::max(1, ratios));
  std::printf("stride 2: %d computed, %d beside none, %d at other shifts, %d interpolated, RMS log ratio %.3f\n",
              counts.computed, counts.beside_none, counts.other_shift, counts.interpolated, counts.rms_log_ratio);
  return counts;
}

// The uncertainty every second node per axis against every node's, on a noisy uniform shift with
// the particles of one corner of the box taken out (windows without signal, so vectors without an
// estimate): the vectors the same bits, most nodes interpolated and near their own sigma, and the
// field's sigma as near the true errors. Then with the far half in y moved 2.5 voxels more along x
// (a step the predictor smooths, so final peaks beside it sit at other integer shifts): those
// nodes computed from their own windows.
TEST(Uncertainty, EverySecondNodeComputedTheRestInterpolated) {
  const Grid3 g = cube(64);
  const sim::UniformFlow flow({0.03, -0.06, 0.12});
  auto pa = sim::particles_around(g, 51);
  std::erase_if(pa, [&](const sim::Point3& p) {
    for (std::size_t a = 0; a < 3; ++a)
      if (p[a] > g.origin_mm[a] + 0.45 * (g.shape[a] - 1) * 0.1) return false;
    return true;
  });
  CorrelationSettings every, second;
  second.uncertainty_stride = 2;
  for (const bool step : {false, true}) {
    auto pb = sim::displace(pa, flow);
    if (step)
      for (sim::Point3& p : pb)
        if (p[1] > g.origin_mm[1] + 0.5 * (g.shape[1] - 1) * 0.1) p[0] += 0.25;
    Volume a = sim::render_exact_volume(g, pa), b = sim::render_exact_volume(g, pb);
    std::mt19937 rng(12);
    std::normal_distribution<float> noise(0, 0.02f);
    for (Volume* v : {&a, &b})
      for (float& x : v->data) x = std::max(0.f, x + noise(rng));
    const CorrelationResult r1 = correlate_volumes(a, b, every), r2 = correlate_volumes(a, b, second);
    EXPECT_EQ(r1.field.dx_mm, r2.field.dx_mm);
    EXPECT_EQ(r1.field.dy_mm, r2.field.dy_mm);
    EXPECT_EQ(r1.field.dz_mm, r2.field.dz_mm);
    EXPECT_NE(r2.field.sigma_method.find("every 2 nodes"), std::string::npos) << r2.field.sigma_method;
    const StrideCounts c = compare_strides(r1.field, r2.field);
    EXPECT_GT(c.beside_none, 10);
    EXPECT_GT(c.interpolated, 4 * c.computed);
    if (step) {
      EXPECT_GT(c.other_shift, 10);
      continue;
    }
    // One window's sigma scatters about its neighbours' (its own few particles); the interpolated
    // value stays near it. Bounds here and below a little above what the case measures (printed).
    EXPECT_LT(c.rms_log_ratio, 0.35);
    const auto check = [&](const CorrelationResult& r) {
      return sim::uncertainty_check(r.field, flow, 0.1, 1, 1, [](const sim::Point3&) { return true; });
    };
    const sim::UncertaintyCheck c1 = check(r1), c2 = check(r2);
    for (int k = 0; k < 3; ++k) {
      std::printf("%c: RMS sigma / error %.3f and %.3f, within 1 sigma %.3f and %.3f, 2 sigma %.3f and %.3f\n",
                  "uvw"[k], c1.rms_sigma[k] / c1.rms_error[k], c2.rms_sigma[k] / c2.rms_error[k], c1.within_1[k],
                  c2.within_1[k], c1.within_2[k], c2.within_2[k]);
      EXPECT_NEAR(c2.rms_sigma[k] / c1.rms_sigma[k], 1, 0.1) << "uvw"[k];
      EXPECT_NEAR(c2.within_1[k], c1.within_1[k], 0.08) << "uvw"[k];
      EXPECT_NEAR(c2.within_2[k], c1.within_2[k], 0.04) << "uvw"[k];
    }
  }
}

// Smoothing carries sigma with the windows' overlap: uniform sigma 1 through one [1 2 1]/4 pass
// per axis of windows 16 wide 4 apart (shares 3/4 and 1/2 at 1 and 2 nodes) leaves
// sqrt(0.8125^3) inside; faces and invalid nodes keep theirs, and a neighbour without an
// estimate gives none.
TEST(Uncertainty, SmoothingCarriesSigmaWithTheWindowsOverlap) {
  const std::array<int, 3> count{5, 5, 5};
  std::vector<float> sigma(125, 1.f);
  std::vector<std::uint8_t> valid(125, 1);
  smooth_sigma(sigma, valid, count, 1, {4, 4, 4}, {16, 16, 16});
  EXPECT_NEAR(sigma[62], std::sqrt(std::pow(0.8125, 3)), 1e-6);  // node (2, 2, 2)
  EXPECT_NEAR(sigma[0], 1.f, 1e-6);                              // a corner: never smoothed
  std::vector<float> with_none(125, 1.f);
  with_none[61] = NAN;  // (1, 2, 2)
  smooth_sigma(with_none, valid, count, 1, {4, 4, 4}, {16, 16, 16});
  EXPECT_TRUE(std::isnan(with_none[62]));
  std::vector<float> beside_invalid(125, 1.f);
  valid[63] = 0;  // (3, 2, 2): (2, 2, 2) is not smoothed along x, only along y and z, so it keeps
                  // more than a node smoothed on every axis
  smooth_sigma(beside_invalid, valid, count, 1, {4, 4, 4}, {16, 16, 16});
  EXPECT_GT(beside_invalid[62], std::sqrt(std::pow(0.8125, 3)) + 0.01);
  EXPECT_LT(beside_invalid[62], 0.8125);
  EXPECT_EQ(beside_invalid[63], 1.f);  // an invalid node keeps what it had
}

// A field of uniform displacement with small noise; planted outliers with good or bad
// secondary peaks.
TEST(Validation, PlantedOutliersAreCaughtAndReplaced) {
  Candidates c({10, 10, 10});
  std::mt19937 rng(4);
  std::normal_distribution<float> noise(0, 0.05f);
  const std::array<float, 3> truth{2.0f, -1.0f, 0.5f};
  for (std::size_t n = 0; n < c.size(); ++n) {
    for (int a = 0; a < 3; ++a) {
      c.peak[0][n][a] = truth[a] + noise(rng);
      c.peak[1][n][a] = 7.f;
      c.peak[2][n][a] = -5.f;
    }
    c.peaks[n] = 3;
  }
  const std::size_t second = c.count[0] * (c.count[1] * 3 + 4) + 5;   // good second peak
  const std::size_t third = c.count[0] * (c.count[1] * 6 + 2) + 7;    // good third peak
  const std::size_t neither = c.count[0] * (c.count[1] * 4 + 7) + 2;  // no good peak
  const std::size_t corner = 0;                                       // on the border
  for (std::size_t n : {second, third, neither, corner}) c.peak[0][n] = {6.f, 3.f, -4.f};
  c.peak[1][second] = truth;
  c.peak[2][third] = truth;
  c.peak[1][corner] = {truth[0], truth[1], 9.f};
  const ValidatedField f = validate(c, MedianTest{});
  EXPECT_EQ(f.counts.outliers, 4u);
  EXPECT_EQ(f.counts.second_peak, 1u);
  EXPECT_EQ(f.counts.third_peak, 1u);
  EXPECT_EQ(f.counts.interpolated, 2u);
  EXPECT_EQ(f.counts.unresolved, 0u);
  EXPECT_TRUE(c.flags[second] & flag_second_peak);
  EXPECT_TRUE(c.flags[third] & flag_third_peak);
  EXPECT_TRUE(c.flags[neither] & flag_interpolated);
  EXPECT_TRUE(c.flags[corner] & flag_interpolated);
  for (std::size_t n : {second, third, neither, corner}) {
    EXPECT_TRUE(f.valid[n]);
    for (int a = 0; a < 3; ++a) EXPECT_NEAR(f.d[n][a], truth[a], 0.1) << n;
  }
}

// revalidate_outliers against validate() afresh: outliers planted with their primary alone (one
// lone, one on a face, a 3x3x3 block of scattered vectors, and two neighbours that disagree in a
// region without signal, so that neither has a settled vector within reach) are validated, then
// gain secondary peaks (some that pass, some that do not); the update gives the bits, flags and
// counts of a fresh validation of the same candidates, a pair node going from unresolved to
// interpolated among them. A node that was not such an outlier is refused.
TEST(Validation, OutliersGivenSecondaryPeaksComeOutAsAFreshValidation) {
  Candidates c({14, 14, 14});
  std::mt19937 rng(9);
  std::normal_distribution<float> noise(0, 0.05f);
  std::uniform_real_distribution<float> wild(-9.f, 9.f);
  const std::array<float, 3> truth{1.0f, 0.5f, -0.5f};
  for (std::size_t n = 0; n < c.size(); ++n) {
    for (int a = 0; a < 3; ++a) c.peak[0][n][a] = truth[a] + noise(rng);
    c.peaks[n] = 1;
  }
  const auto at = [&](int x, int y, int z) { return (std::size_t(z) * c.count[1] + y) * c.count[0] + x; };
  std::vector<std::size_t> planted{at(2, 10, 3), at(0, 7, 4)};
  for (int z = 3; z < 6; ++z)
    for (int y = 3; y < 6; ++y)
      for (int x = 3; x < 6; ++x) planted.push_back(at(x, y, z));
  for (std::size_t n : planted) c.peak[0][n] = {wild(rng) + 12.f, wild(rng), wild(rng) - 12.f};
  // No signal in the corner region but for the pair.
  for (int z = 7; z < 14; ++z)
    for (int y = 7; y < 14; ++y)
      for (int x = 7; x < 14; ++x) c.peaks[at(x, y, z)] = 0;
  const std::size_t first = at(10, 10, 10), second = at(11, 10, 10);
  c.peaks[first] = c.peaks[second] = 1;
  c.peak[0][first] = truth;
  c.peak[0][second] = {truth[0] + 3.f, truth[1], truth[2]};
  planted.push_back(first);
  planted.push_back(second);
  Candidates before = c;
  ValidatedField f = validate(before, MedianTest{});
  for (std::size_t n : planted) ASSERT_TRUE(before.flags[n] & (flag_interpolated | flag_unresolved)) << n;
  ASSERT_TRUE(before.flags[second] & flag_unresolved);
  // Secondary peaks: far off, but the truth as the lone node's second, the face node's third, a
  // block corner's and the block centre's second, and the first pair node's second the second's
  // primary.
  for (Candidates* k : {&before, &c}) {
    for (std::size_t n : planted) {
      k->peaks[n] = 3;
      k->peak[1][n] = k->peak[2][n] = {-7.f, 2.f, 9.f};
    }
    for (std::size_t n : {planted[0], at(3, 3, 3), at(4, 4, 4)}) k->peak[1][n] = truth;
    k->peak[2][planted[1]] = truth;
    k->peak[1][first] = c.peak[0][second];
  }
  revalidate_outliers(before, MedianTest{}, planted, f);
  const ValidatedField fresh = validate(c, MedianTest{});
  EXPECT_TRUE(testing_support::same_bits(f.d, fresh.d));
  EXPECT_EQ(f.valid, fresh.valid);
  EXPECT_EQ(before.flags, c.flags);
  EXPECT_EQ(f.counts.outliers, fresh.counts.outliers);
  EXPECT_EQ(f.counts.second_peak, fresh.counts.second_peak);
  EXPECT_EQ(f.counts.third_peak, fresh.counts.third_peak);
  EXPECT_EQ(f.counts.interpolated, fresh.counts.interpolated);
  EXPECT_EQ(f.counts.unresolved, fresh.counts.unresolved);
  EXPECT_EQ(fresh.counts.second_peak, 4u);
  EXPECT_EQ(fresh.counts.third_peak, 1u);
  EXPECT_TRUE(c.flags[second] & flag_interpolated) << "the pair's second node gains a settled neighbour";
  EXPECT_THROW(revalidate_outliers(before, MedianTest{}, std::vector<std::size_t>{at(1, 1, 1)}, f), std::logic_error);
}

// validate() against the normalised median test written out for every node: the neighbours'
// primaries within the radius (clipped at the faces, so odd and even counts), each axis's median
// (the mean of the two middle values for an even count) and median absolute residual, a vector
// passing when |u - median| / (spread + epsilon) <= threshold on every axis; an outlier takes the
// first secondary peak that passes, else waits for interpolation. Values on a coarse grid put
// many residuals exactly at, and one float step about, threshold x epsilon and threshold x
// (spread + epsilon), where validate() decides from counts or falls back to the selections.
TEST(Validation, EveryNodeGetsTheNormalisedMedianTestsOutcome) {
  std::mt19937 rng(9);
  int boundary = 0, spread_boundary = 0, outliers = 0, nodes = 0;
  for (int trial = 0; trial < 24; ++trial) {
    Candidates c({6, 5, 7});
    const float step = trial % 2 ? 0.05f : 0.1f;
    // Most primaries within a step of 0 (a spread of at most a step: the first step of the test,
    // |u - median| <= threshold x epsilon, decides most of them), a fifth of them far out.
    std::uniform_int_distribution<int> narrow(-1, 1), wide(-8, 8), pick(0, 4);
    for (std::size_t n = 0; n < c.size(); ++n) {
      c.peaks[n] = std::uint8_t(trial % 4 == 3 && n % 5 == 0 ? 0 : 1 + n % 3);
      for (auto& rank : c.peak)
        for (float& v : rank[n]) v = float(pick(rng) ? narrow(rng) : wide(rng)) * step;
    }
    MedianTest test;
    test.radius = 1 + trial % 2;
    const auto median_of = [](std::vector<float> v) {
      std::sort(v.begin(), v.end());
      const std::size_t h = v.size() / 2;
      return v.size() % 2 ? v[h] : 0.5f * (v[h - 1] + v[h]);
    };
    Candidates copy = c;
    const ValidatedField f = validate(copy, test);
    for (int k = 0; k < c.count[2]; ++k)
      for (int j = 0; j < c.count[1]; ++j)
        for (int i = 0; i < c.count[0]; ++i) {
          const std::size_t node = (std::size_t(k) * c.count[1] + j) * c.count[0] + i;
          if (!c.peaks[node]) continue;
          ++nodes;
          std::array<std::vector<float>, 3> values;
          for (int z = std::max(k - test.radius, 0); z <= std::min(k + test.radius, c.count[2] - 1); ++z)
            for (int y = std::max(j - test.radius, 0); y <= std::min(j + test.radius, c.count[1] - 1); ++y)
              for (int x = std::max(i - test.radius, 0); x <= std::min(i + test.radius, c.count[0] - 1); ++x) {
                const std::size_t m = (std::size_t(z) * c.count[1] + y) * c.count[0] + x;
                if (m == node || !c.peaks[m]) continue;
                for (int a = 0; a < 3; ++a) values[a].push_back(c.peak[0][m][a]);
              }
          std::array<float, 3> med{}, spread{};
          for (int a = 0; a < 3 && !values[0].empty(); ++a) {
            med[a] = median_of(values[a]);
            std::vector<float> residual;
            for (float v : values[a]) residual.push_back(std::abs(v - med[a]));
            spread[a] = median_of(residual);
          }
          const auto passes = [&](const std::array<float, 3>& u) {
            if (values[0].empty()) return true;
            for (int a = 0; a < 3; ++a) {
              const float r = std::abs(u[a] - med[a]);
              boundary += std::abs(r / test.epsilon - test.threshold) < 1e-5;
              spread_boundary +=
                  r / test.epsilon > test.threshold && std::abs(r / (spread[a] + test.epsilon) - test.threshold) < 1e-5;
              if (!(r / (spread[a] + test.epsilon) <= test.threshold)) return false;
            }
            return true;
          };
          SCOPED_TRACE("trial " + std::to_string(trial) + ", node " + std::to_string(node));
          if (passes(c.peak[0][node])) {
            EXPECT_TRUE(f.valid[node]);
            EXPECT_EQ(copy.flags[node], 0);
            EXPECT_EQ(f.d[node], c.peak[0][node]);
            continue;
          }
          ++outliers;
          int rank = 1;
          while (rank < c.peaks[node] && !passes(c.peak[rank][node])) ++rank;
          if (rank < c.peaks[node]) {
            EXPECT_TRUE(copy.flags[node] & (rank == 1 ? flag_second_peak : flag_third_peak));
            EXPECT_EQ(f.d[node], c.peak[rank][node]);
          } else {
            EXPECT_TRUE(copy.flags[node] & (flag_interpolated | flag_unresolved));
          }
        }
  }
  EXPECT_GT(outliers, nodes / 20);  // both outcomes are compared
  EXPECT_LT(outliers, nodes * 9 / 10);
  EXPECT_GT(boundary, 100);         // residuals at threshold x epsilon
  EXPECT_GT(spread_boundary, 100);  // and at threshold x (spread + epsilon)
}

TEST(Validation, ASpoiledWindowIsCaughtAndReplaced) {
  const Grid3 g = cube(48);
  const auto pa = random_points(g, 300, 21);
  std::vector<P3> pb = pa;
  for (auto& p : pb) p[0] += 1.5;
  Volume a = blobs(g, pa), b = blobs(g, pb);
  CorrelationSettings s;
  s.passes = {{{16, 16, 16}, 50}, {{16, 16, 16}, 50}};
  const auto clean = correlate_volumes(a, b, s);
  // Spoil the window around node (2, 2, 2) (voxels 16..31): its particles in b are replaced by
  // one bright particle 3 voxels off, which pulls that window's primary peak away.
  for (int z = 18; z < 30; ++z)
    for (int y = 18; y < 30; ++y)
      for (int x = 18; x < 30; ++x) b.at(x, y, z) = 0;
  const Volume spot = blobs(g, {{24.0, 27.0, 24.0}});
  for (std::size_t i = 0; i < b.data.size(); ++i) b.data[i] += 40 * spot.data[i];
  const auto spoiled = correlate_volumes(a, b, s);
  const std::size_t node = spoiled.field.grid.index(2, 2, 2);
  EXPECT_GT(spoiled.passes.back().validation.outliers, clean.passes.back().validation.outliers);
  EXPECT_TRUE(spoiled.flags[node] & (flag_second_peak | flag_third_peak | flag_interpolated));
  EXPECT_TRUE(spoiled.field.valid[node]);
  EXPECT_NEAR(spoiled.field.dx_mm[node] / g.spacing_mm[0], 1.5, 0.2);
  EXPECT_NEAR(spoiled.field.dy_mm[node] / g.spacing_mm[1], 0.0, 0.2);
}

// The final smoothing (CorrelationSettings::final_smoothing) on node fields built here: a linear
// field comes out unchanged, faces and invalid nodes included; an invalid node lends nothing and
// stays as it was; independent noise drops by the binomial kernel's factor.
TEST(Validation, SmoothingKeepsALinearFieldAndLowersIndependentNoise) {
  const std::array<int, 3> count{12, 10, 8};
  const std::size_t n = std::size_t(count[0]) * count[1] * count[2];
  const auto linear = [&](std::size_t node, int a) {
    const int x = int(node % count[0]), y = int(node / count[0] % count[1]), z = int(node / (count[0] * count[1]));
    return float(0.5 * a + 0.1 * x - 0.2 * y + 0.3 * z);
  };
  ValidatedField f;
  f.d.resize(n);
  f.valid.assign(n, 1);
  for (std::size_t m = 0; m < n; ++m)
    for (int a = 0; a < 3; ++a) f.d[m][a] = linear(m, a);
  const std::size_t hole = (std::size_t(4) * count[1] + 5) * count[0] + 6;
  f.valid[hole] = 0;
  f.d[hole] = {99.f, 99.f, 99.f};
  smooth_valid(f, count, 2);
  EXPECT_EQ(f.valid[hole], 0);
  for (int a = 0; a < 3; ++a) EXPECT_EQ(f.d[hole][a], 99.f);
  for (std::size_t m = 0; m < n; ++m) {
    if (m == hole) continue;
    for (int a = 0; a < 3; ++a) ASSERT_NEAR(f.d[m][a], linear(m, a), 1e-5) << m << " " << a;
  }

  // Independent noise about a uniform field: one pass leaves (6/16)^(3/2) = 0.230 of its RMS at
  // the nodes off the faces (each axis's [1 2 1]/4 keeps (1 + 4 + 1)/16 of the variance).
  const std::array<int, 3> big{24, 24, 24};
  ValidatedField g;
  g.d.resize(std::size_t(big[0]) * big[1] * big[2]);
  g.valid.assign(g.d.size(), 1);
  std::mt19937 rng(3);
  std::normal_distribution<float> noise(0.f, 1.f);
  for (auto& d : g.d)
    for (float& v : d) v = noise(rng);
  smooth_valid(g, big, 1);
  double sum_sq = 0;
  std::size_t inner = 0;
  for (int z = 1; z < big[2] - 1; ++z)
    for (int y = 1; y < big[1] - 1; ++y)
      for (int x = 1; x < big[0] - 1; ++x, ++inner)
        for (float v : g.d[(std::size_t(z) * big[1] + y) * big[0] + x]) sum_sq += double(v) * v;
  const double rms = std::sqrt(sum_sq / (3.0 * double(inner)));
  std::printf("noise RMS after one smoothing pass: %.4f (expected 0.2296)\n", rms);
  EXPECT_NEAR(rms, 0.2296, 0.01);
}

TEST(Vorticity, SolidBodyRotationHasTwiceTheAngularVelocity) {
  Grid3 g;
  g.shape = {9, 8, 7};
  g.spacing_mm = {0.5, 0.4, 0.6};
  g.origin_mm = {-2, -1.4, -1.8};
  VectorField f(g);
  f.dt_s = 0.01;
  const double omega = 3.0;  // rad/s about z: u = -omega y, v = omega x
  for (int z = 0; z < g.shape[2]; ++z)
    for (int y = 0; y < g.shape[1]; ++y)
      for (int x = 0; x < g.shape[0]; ++x) {
        const std::size_t i = g.index(x, y, z);
        f.dx_mm[i] = float(-omega * g.coordinate_mm(1, y) * f.dt_s);
        f.dy_mm[i] = float(omega * g.coordinate_mm(0, x) * f.dt_s);
        f.valid[i] = 1;
      }
  f.valid[g.index(4, 4, 3)] = 0;
  const auto w = vorticity(f);
  EXPECT_TRUE(std::isnan(w[2][g.index(4, 4, 3)]));
  for (std::size_t i = 0; i < g.count(); ++i) {
    if (!f.valid[i]) continue;
    EXPECT_NEAR(w[0][i], 0, 1e-4);
    EXPECT_NEAR(w[1][i], 0, 1e-4);
    EXPECT_NEAR(w[2][i], 2 * omega, 1e-3);
  }
}

TEST(Settings, PassesFromTextAndRefusals) {
  const auto p = parse_passes("32@50,16x16x32@75");
  ASSERT_EQ(p.size(), 2u);
  EXPECT_EQ(p[1].window[2], 32);
  EXPECT_EQ(p[1].overlap_percent, 75);
  EXPECT_THROW(parse_passes("32"), InputError);
  EXPECT_THROW(parse_passes("32x16@50"), InputError);
  EXPECT_THROW(parse_passes("2@50"), InputError);
  EXPECT_THROW(parse_passes("16@100"), InputError);
  const auto m = parse_passes("32@50,16@50+4,16@75");
  EXPECT_EQ(m[0].depth_margin, 0);
  EXPECT_EQ(m[1].depth_margin, 4);
  EXPECT_EQ(m[1].overlap_percent, 50);
  EXPECT_EQ(m[2].depth_margin, 0);
  EXPECT_THROW(parse_passes("16@50+"), InputError);
  EXPECT_THROW(parse_passes("16@50+four"), InputError);
  EXPECT_THROW(parse_passes("16@50+4.5"), InputError);
  EXPECT_THROW(parse_passes("16@50+-1"), InputError);
  EXPECT_THROW(parse_passes("16@50+17"), InputError);  // more than the window's depth
}

TEST(Settings, SpectralWhiteningFromYamlAndRefusals) {
  auto from = [](const std::string& text) {
    return correlation_settings_from(YamlMap(load_yaml_text(text, "piv.yaml"), "piv.yaml"));
  };
  const CorrelationSettings d = from("{}");
  EXPECT_EQ(d.spectral_whitening, 0.0);  // off: the paper's correlation
  const std::array<double, 3> deeper{1, 1, 2};
  EXPECT_EQ(d.whitened_peak_sigma_voxel, deeper);
  const CorrelationSettings s = from("spectral_whitening: 0.5\nwhitened_peak_sigma_voxel: [1.5, 1, 3]\n");
  EXPECT_EQ(s.spectral_whitening, 0.5);
  const std::array<double, 3> given{1.5, 1, 3};
  EXPECT_EQ(s.whitened_peak_sigma_voxel, given);
  const std::array<double, 3> same{2, 2, 2};
  EXPECT_EQ(from("whitened_peak_sigma_voxel: 2\n").whitened_peak_sigma_voxel, same);
  for (const std::string bad :
       {"spectral_whitening: -0.1\n", "spectral_whitening: 1.5\n", "spectral_whitening: strong\n",
        "whitened_peak_sigma_voxel: 0.2\n", "whitened_peak_sigma_voxel: [1, 1]\n",
        "whitened_peak_sigma_voxel: [1, wide, 1]\n", "whitened_peak_sigma_voxel: [1, 1, 9]\n"}) {
    try {
      from(bad);
      ADD_FAILURE() << "accepted: " << bad;
    } catch (const InputError& e) {
      const std::string key = bad.substr(0, bad.find(':'));
      EXPECT_NE(std::string(e.what()).find(key), std::string::npos) << e.what();
    }
  }
}

TEST(Settings, EveryCorrelationChoiceHasOneNameAndAnUnknownNameIsRefusedByName) {
  for (const PredictorBase base : {PredictorBase::window_mean, PredictorBase::centre})
    EXPECT_EQ(predictor_base_named(name_of(base), "predictor"), base);
  for (const Interpolation interpolation : {Interpolation::sinc, Interpolation::cubic})
    EXPECT_EQ(interpolation_named(name_of(interpolation), "early_interpolation"), interpolation);
  for (const FinalPeakSearch search : {FinalPeakSearch::all_shifts, FinalPeakSearch::near_predictor})
    EXPECT_EQ(final_peak_search_named(name_of(search), "final_peak_search"), search);
  EXPECT_EQ(name_of(PredictorBase::centre), "centre");
  EXPECT_EQ(name_of(Interpolation::cubic), "cubic");
  EXPECT_EQ(name_of(FinalPeakSearch::near_predictor), "near_predictor");
  try {
    (void)interpolation_named("linear", "--early-interpolation");
    FAIL() << "an unknown interpolation was taken";
  } catch (const InputError& e) {
    EXPECT_STREQ(e.what(), "--early-interpolation: expected one of sinc, cubic, got 'linear'");
  }
  EXPECT_THROW((void)final_peak_search_named("Near_Predictor", "final_peak_search"), InputError);  // exact
  // A config without the keys takes CorrelationSettings' defaults, named by the same table.
  const CorrelationSettings defaults;
  const CorrelationSettings d = correlation_settings_from(YamlMap(load_yaml_text("{}", "piv.yaml"), "piv.yaml"));
  EXPECT_EQ(d.predictor, defaults.predictor);
  EXPECT_EQ(d.early_interpolation, defaults.early_interpolation);
  EXPECT_EQ(d.final_peak_search, defaults.final_peak_search);
  EXPECT_EQ(correlation_settings_from(YamlMap(load_yaml_text("early_interpolation: cubic\n", "piv.yaml"), "piv.yaml"))
                .early_interpolation,
            Interpolation::cubic);
}

TEST(Settings, FinalPeakSearchFromYamlAndRefusals) {
  auto from = [](const std::string& text) {
    return correlation_settings_from(YamlMap(load_yaml_text(text, "piv.yaml"), "piv.yaml"));
  };
  EXPECT_EQ(from("{}").final_peak_search, FinalPeakSearch::all_shifts);
  EXPECT_EQ(from("final_peak_search: near_predictor\n").final_peak_search, FinalPeakSearch::near_predictor);
  EXPECT_EQ(from("final_peak_search: all_shifts\n").final_peak_search, FinalPeakSearch::all_shifts);
  for (const std::string bad :
       {"final_peak_search: nearby\n", "final_peak_search: 1\n",
        "final_peak_search: near_predictor\npasses: [{window: 16, overlap_percent: 50, depth_margin: 2}]\n"}) {
    try {
      from(bad);
      ADD_FAILURE() << "accepted: " << bad;
    } catch (const InputError& e) {
      EXPECT_NE(std::string(e.what()).find("final_peak_search"), std::string::npos) << e.what();
    }
  }
}

TEST(Settings, PredictorKeysFromYamlAndRefusals) {
  auto from = [](const std::string& text) {
    return correlation_settings_from(YamlMap(load_yaml_text(text, "piv.yaml"), "piv.yaml"));
  };
  const CorrelationSettings d = from("{}");
  EXPECT_EQ(d.predictor, PredictorBase::centre);
  EXPECT_EQ(d.predictor_smoothing, 1);
  EXPECT_EQ(d.passes.size(), 4u);
  EXPECT_EQ(d.passes[1].depth_margin, 4);
  EXPECT_EQ(d.passes[2].depth_margin, 0);
  EXPECT_EQ(d.passes[3].depth_margin, 0);
  EXPECT_EQ(from("passes: [{window: 16, overlap_percent: 50, depth_margin: 6}]\n").passes[0].depth_margin, 6);
  EXPECT_THROW(from("passes: [{window: 16, overlap_percent: 50, depth_margin: -1}]\n"), InputError);
  EXPECT_THROW(from("passes: [{window: 16, overlap_percent: 50, depth_margin: 17}]\n"), InputError);
  EXPECT_THROW(from("passes: [{window: 16, overlap_percent: 50, depth_margin: 1e10}]\n"), InputError);
  const CorrelationSettings m = from("predictor: window_mean\npredictor_smoothing: 0\n");
  EXPECT_EQ(m.predictor, PredictorBase::window_mean);
  EXPECT_EQ(m.predictor_smoothing, 0);
  EXPECT_THROW(from("predictor: middle\n"), InputError);
  EXPECT_THROW(from("predictor_smoothing: 5\n"), InputError);
  EXPECT_THROW(from("predictor_smoothing: -1\n"), InputError);
  EXPECT_THROW(from("predictor_smoothing: 4294967297\n"), InputError);  // 1 if cast to int unchecked
  EXPECT_THROW(from("median: {radius: 4294967298}\n"), InputError);     // 2 likewise
  EXPECT_EQ(from("median: {radius: 3}\n").median.radius, 3);
  EXPECT_EQ(d.intensity_threshold_of_mean, 0.0);
  EXPECT_EQ(from("intensity_threshold_of_mean: 4\n").intensity_threshold_of_mean, 4.0);
  EXPECT_THROW(from("intensity_threshold_of_mean: -1\n"), InputError);
  EXPECT_THROW(from("intensity_threshold_of_mean: 101\n"), InputError);
  EXPECT_THROW(from("intensity_threshold_of_mean: many\n"), InputError);
  EXPECT_EQ(d.final_smoothing, 0);
  EXPECT_EQ(from("final_smoothing: 2\n").final_smoothing, 2);
  EXPECT_TRUE(d.uncertainty);
  EXPECT_FALSE(from("uncertainty: false\n").uncertainty);
  EXPECT_THROW(from("uncertainty: sometimes\n"), InputError);
  EXPECT_EQ(d.uncertainty_stride, 1);
  EXPECT_EQ(from("uncertainty_stride: 2\n").uncertainty_stride, 2);
  EXPECT_THROW(from("uncertainty_stride: 0\n"), InputError);
  EXPECT_THROW(from("uncertainty_stride: 5\n"), InputError);
  EXPECT_THROW(from("uncertainty_stride: 1.5\n"), InputError);
  EXPECT_EQ(d.early_interpolation, Interpolation::sinc);
  EXPECT_EQ(from("early_interpolation: cubic\n").early_interpolation, Interpolation::cubic);
  EXPECT_THROW(from("early_interpolation: linear\n"), InputError);
  EXPECT_THROW(from("final_smoothing: -1\n"), InputError);
  EXPECT_THROW(from("final_smoothing: 5\n"), InputError);
  EXPECT_THROW(from("final_smoothing: 1e10\n"), InputError);
  EXPECT_THROW(from("final_smoothing: 4294967297\n"), InputError);
  EXPECT_THROW(from("final_smoothing: 1.5\n"), InputError);
  EXPECT_THROW(from("final_smoothing: many\n"), InputError);
  EXPECT_EQ(d.depth_prefilter, 0);
  EXPECT_EQ(from("depth_prefilter: 4\n").depth_prefilter, 4);
  EXPECT_EQ(from("depth_prefilter: 8\n").depth_prefilter, 8);
  EXPECT_THROW(from("depth_prefilter: -1\n"), InputError);
  EXPECT_THROW(from("depth_prefilter: 9\n"), InputError);
  EXPECT_THROW(from("depth_prefilter: 4294967300\n"), InputError);  // 4 if cast to int unchecked
  EXPECT_THROW(from("depth_prefilter: 2.5\n"), InputError);
  try {
    from("prefilter: false\ndepth_prefilter: 2\n");
    ADD_FAILURE() << "depth passes without the prefilter were accepted";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("depth_prefilter"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("piv.yaml"), std::string::npos) << e.what();
  }
  EXPECT_FALSE(from("prefilter: false\ndepth_prefilter: 0\n").prefilter);
}

}  // namespace
}  // namespace plenopiv::piv
