// MART's elementwise logarithms and exponentials (kernels::log_ratios, log_or_zero, log_pixels,
// multiply_by_exp, extrapolate): each pixel's case, the bounds, the same bits wherever a range is
// split, and SLEEF's functions the same bits in every vector width the kernels dispatch to.
#include <gtest/gtest.h>
#include <sleef.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <random>
#include <vector>

#include "core/recon/kernels.hpp"
#include "core/recon/sleef_wide.hpp"

namespace plenopiv::recon::kernels {
namespace {

constexpr float kMaxLog = 40.f, kTiny = 1e-30f, kHuge = 1e30f;

// Pixels of every case: between lens images (white 0), lit with P > 0 and P = 0, dark with P above
// and below the floor, log-ratios beyond ±kMaxLog; n not a multiple of four.
struct Pixels {
  std::vector<float> projection, data, log_data, white, scale;
  float dark_floor = 0.5f, log_floor = std::log(0.5f);
  explicit Pixels(std::size_t n) : projection(n), data(n), log_data(n), white(n), scale(n) {
    std::mt19937 random(7);
    std::uniform_real_distribution<float> unit(0.f, 1.f), exponent(-40.f, 40.f);
    for (std::size_t i = 0; i < n; ++i) {
      const int kind = int(i % 7);
      projection[i] = kind == 1 ? 0.f : (kind == 2 ? 1e-35f : std::exp(exponent(random)));
      data[i] = kind == 3 || kind == 4 ? 0.f : std::exp(exponent(random));
      if (kind == 4) projection[i] = 0.25f * unit(random);  // dark, below the floor
      white[i] = kind == 5 ? 0.f : unit(random);
      scale[i] = unit(random);
    }
    log_or_zero(data.data(), 0, n, log_data.data());
  }
  LogRatioInputs inputs(bool scaled) const {
    return {projection.data(), data.data(), log_data.data(), white.data(), scaled ? scale.data() : nullptr,
            kMaxLog,           log_floor,   dark_floor,      kTiny};
  }
};

std::vector<std::size_t> random_cuts(std::mt19937& random, std::size_t n) {
  std::uniform_int_distribution<std::size_t> at(0, n);
  std::vector<std::size_t> cuts{0, n, at(random), at(random), at(random)};
  std::sort(cuts.begin(), cuts.end());
  return cuts;
}

// The same bits, or both NaN: a NaN's payload may differ between widths (the kernels never take
// ln or exp of a NaN: their arguments are clamped, and images and volumes are checked finite).
bool same(float a, float b) { return std::memcmp(&a, &b, sizeof a) == 0 || (std::isnan(a) && std::isnan(b)); }

// The kernels take ln and exp in the widest vectors the CPU has (vector_math.cpp, sleef_wide.hpp):
// the same bits as the SSE2 functions every x86-64 CPU has, so results do not depend on the CPU.
// Over every 257th float bit pattern of either sign (zeros, denormals, infinities, NaNs among them).
TEST(VectorMath, SleefsFunctionsGiveTheSameBitsInEveryVectorWidth) {
  const bool has_avx = __builtin_cpu_supports("avx"), has_avx512 = __builtin_cpu_supports("avx512f");
  if (!has_avx && !has_avx512) GTEST_SKIP() << "this CPU has neither AVX nor AVX-512: only the SSE2 path runs here";
  std::size_t compared = 0;
  float in[16], ln[16], ex[16], ln_wide[16], ex_wide[16];
  for (std::uint64_t bits = 0; bits <= 0xffffffffu; bits += 16 * 257) {
    for (int i = 0; i < 16; ++i) {
      const std::uint32_t b = std::uint32_t(bits + std::uint64_t(i) * 257);
      std::memcpy(&in[i], &b, sizeof b);
    }
    for (int i = 0; i < 16; i += 4) {
      _mm_storeu_ps(ln + i, Sleef_cinz_logf4_u35sse2(_mm_loadu_ps(in + i)));
      _mm_storeu_ps(ex + i, Sleef_cinz_expf4_u10sse2(_mm_loadu_ps(in + i)));
    }
    for (const bool avx512 : {false, true}) {
      if (avx512 ? !has_avx512 : !has_avx) continue;
      std::memcpy(ln_wide, in, sizeof in);
      std::memcpy(ex_wide, in, sizeof in);
      (avx512 ? log_avx512 : log_avx)(ln_wide, 16);
      (avx512 ? exp_avx512 : exp_avx)(ex_wide, 16);
      for (int i = 0; i < 16; ++i) {
        ASSERT_TRUE(same(ln[i], ln_wide[i])) << "ln of " << in[i] << (avx512 ? ", AVX-512" : ", AVX");
        ASSERT_TRUE(same(ex[i], ex_wide[i])) << "exp of " << in[i] << (avx512 ? ", AVX-512" : ", AVX");
      }
      compared += 16;
    }
  }
  EXPECT_GT(compared, 1000000u);
}

TEST(VectorMath, EachPixelsCaseAndTheBoundsOfTheLogRatio) {
  const Pixels px(1003);
  for (const bool scaled : {false, true}) {
    std::vector<float> ratio(px.data.size());
    log_ratios(px.inputs(scaled), 0, ratio.size(), ratio.data());
    for (std::size_t i = 0; i < ratio.size(); ++i) {
      const float p = px.projection[i], k = scaled ? px.scale[i] : 1.f;
      double expected = 0;
      if (px.white[i] == 0.f) {
        expected = 0;
      } else if (px.data[i] > 0.f) {
        expected =
            p > 0.f ? k * std::clamp(std::log(double(px.data[i])) - std::log(std::max(double(p), 1e-30)), -40.0, 40.0)
                    : 0.0;
      } else {
        expected = p > px.dark_floor ? k * std::max(double(px.log_floor) - std::log(double(p)), -40.0) : 0.0;
      }
      if (expected == 0) {
        EXPECT_EQ(ratio[i], 0.f) << "pixel " << i;
      } else {
        // ln within a few ulp of values up to 69: 2e-5 absolute.
        EXPECT_NEAR(ratio[i], expected, 2e-5 + 1e-6 * std::abs(expected)) << "pixel " << i;
        EXPECT_LE(std::abs(ratio[i]), k * kMaxLog) << "pixel " << i;
      }
    }
  }
}

// Voxels at 0 and across the float range, updates past both bounds of the exponent: e exp(mu u)
// within the exp's 1 ulp and the product's rounding, 0 below kTiny, kHuge above it.
std::vector<float> voxels(std::mt19937& random, std::size_t n) {
  std::uniform_real_distribution<float> exponent(-60.f, 60.f);
  std::vector<float> e(n);
  for (std::size_t i = 0; i < n; ++i) e[i] = i % 5 == 0 ? 0.f : std::exp(exponent(random));
  return e;
}

TEST(VectorMath, EachVoxelsMultiplicativeUpdateAndItsBounds) {
  std::mt19937 random(5);
  const std::size_t n = 1003;
  const std::vector<float> e = voxels(random, n);
  std::uniform_real_distribution<float> change(-120.f, 120.f);
  std::vector<float> update(n);
  for (float& u : update) u = change(random);
  const float mu = 0.5f;
  std::vector<float> out = e;
  multiply_by_exp({out.data(), update.data(), mu, kMaxLog, kTiny, kHuge}, 0, n);
  int checked = 0;
  for (std::size_t i = 0; i < n; ++i) {
    const double expected = double(e[i]) * std::exp(std::clamp(double(mu) * update[i], -40.0, 40.0));
    if (expected < kTiny * (1 - 1e-5)) {
      EXPECT_EQ(out[i], 0.f) << "voxel " << i;
    } else if (expected > kHuge * (1 + 1e-5)) {
      EXPECT_EQ(out[i], kHuge) << "voxel " << i;
    } else if (expected > kTiny * (1 + 1e-5) && expected < kHuge * (1 - 1e-5)) {
      EXPECT_NEAR(out[i], expected, 3e-7 * expected) << "voxel " << i;
      ++checked;
    }
  }
  EXPECT_GT(checked, int(n / 2));
}

TEST(VectorMath, EachPixelsLogarithmForTheLineOfSightStart) {
  const Pixels px(1003);
  const float log_floor = -3.5f;
  std::vector<float> data = px.data;
  data[6] = 1e-40f;  // a denormal pixel: taken at kTiny
  std::vector<float> out(data.size());
  log_pixels(data.data(), px.white.data(), log_floor, kTiny, 0, out.size(), out.data());
  for (std::size_t i = 0; i < out.size(); ++i) {
    const double expected =
        (data[i] > 0.f ? std::log(std::max(double(data[i]), double(kTiny))) : double(log_floor)) * px.white[i];
    EXPECT_NEAR(out[i], expected, 2e-5 + 1e-6 * std::abs(expected)) << "pixel " << i;
  }
}

TEST(VectorMath, AProjectionThatMatchesItsPixelGivesALogRatioOfExactlyZero) {
  Pixels px(101);
  px.projection = px.data;  // every lit pixel matched
  std::vector<float> ratio(px.data.size(), 1.f);
  log_ratios(px.inputs(false), 0, ratio.size(), ratio.data());
  for (std::size_t i = 0; i < ratio.size(); ++i) {
    if (px.data[i] > kTiny) {
      EXPECT_EQ(ratio[i], 0.f) << "pixel " << i;
    }
  }
}

TEST(VectorMath, TheSameBitsWhereverARangeIsSplit) {
  const Pixels px(1003);
  const std::size_t n = px.data.size();
  std::vector<float> whole(n), logs(n);
  log_ratios(px.inputs(true), 0, n, whole.data());
  log_or_zero(px.data.data(), 0, n, logs.data());
  // The accelerated step's state: voxels at 0 and at least kTiny, some unchanged since the last.
  std::mt19937 random(3);
  std::uniform_real_distribution<float> exponent(-60.f, 60.f);
  std::vector<float> e(n), last(n);
  for (std::size_t i = 0; i < n; ++i) {
    e[i] = i % 5 == 0 ? 0.f : std::exp(exponent(random));
    last[i] = i % 3 == 0 ? e[i] : (i % 11 == 0 ? 0.f : std::exp(exponent(random)));
  }
  std::vector<float> log_last(n), momentum(n);
  log_or_zero(last.data(), 0, n, log_last.data());
  std::vector<float> step_e = e, step_last = last, step_log_last = log_last, step_momentum(n);
  extrapolate(
      {step_e.data(), step_last.data(), step_log_last.data(), step_momentum.data(), 0.6f, kMaxLog, kTiny, kHuge}, 0, n);
  for (std::size_t i = 0; i < n; ++i) {
    if (i % 3 == 0 && e[i] > 0.f) {
      EXPECT_EQ(step_momentum[i], 0.f) << "an unchanged voxel " << i << " has no momentum";
      EXPECT_EQ(step_e[i], e[i]) << "voxel " << i;
    }
    EXPECT_TRUE(step_e[i] == 0.f || (step_e[i] >= kTiny && step_e[i] <= kHuge)) << "voxel " << i << ": " << step_e[i];
  }
  // The update and the start's pixel logarithms, whole.
  std::vector<float> updated = e, pixel_logs(n);
  multiply_by_exp({updated.data(), logs.data(), 0.7f, kMaxLog, kTiny, kHuge}, 0, n);
  log_pixels(px.data.data(), px.white.data(), -3.5f, kTiny, 0, n, pixel_logs.data());
  for (int trial = 0; trial < 20; ++trial) {
    const std::vector<std::size_t> cuts = random_cuts(random, n);
    std::vector<float> split(n), split_logs(n), split_pixel_logs(n);
    std::vector<float> se = e, sl = last, sll = log_last, sm(n), su = e;
    for (std::size_t c = 0; c + 1 < cuts.size(); ++c) {
      log_ratios(px.inputs(true), cuts[c], cuts[c + 1], split.data());
      log_or_zero(px.data.data(), cuts[c], cuts[c + 1], split_logs.data());
      extrapolate({se.data(), sl.data(), sll.data(), sm.data(), 0.6f, kMaxLog, kTiny, kHuge}, cuts[c], cuts[c + 1]);
      multiply_by_exp({su.data(), logs.data(), 0.7f, kMaxLog, kTiny, kHuge}, cuts[c], cuts[c + 1]);
      log_pixels(px.data.data(), px.white.data(), -3.5f, kTiny, cuts[c], cuts[c + 1], split_pixel_logs.data());
    }
    EXPECT_EQ(0, std::memcmp(split.data(), whole.data(), n * sizeof(float))) << "trial " << trial;
    EXPECT_EQ(0, std::memcmp(split_logs.data(), logs.data(), n * sizeof(float))) << "trial " << trial;
    EXPECT_EQ(0, std::memcmp(se.data(), step_e.data(), n * sizeof(float))) << "trial " << trial;
    EXPECT_EQ(0, std::memcmp(sm.data(), step_momentum.data(), n * sizeof(float))) << "trial " << trial;
    EXPECT_EQ(0, std::memcmp(su.data(), updated.data(), n * sizeof(float))) << "trial " << trial;
    EXPECT_EQ(0, std::memcmp(split_pixel_logs.data(), pixel_logs.data(), n * sizeof(float))) << "trial " << trial;
  }
}

}  // namespace
}  // namespace plenopiv::recon::kernels
