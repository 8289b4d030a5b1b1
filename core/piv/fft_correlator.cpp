// FFT cross-correlation of 3-D interrogation windows (FFTW, float): a + i b in one transform.
#include "core/piv/fft_correlator.hpp"

#include <fftw3.h>
#include <tbb/enumerable_thread_specific.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>
#include <mutex>
#include <new>
#include <numbers>
#include <utility>

#include "core/base/isa.hpp"

namespace plenopiv::piv {
namespace {

// FFTW's planner (and plan destruction) must not run concurrently, in this library or any other.
std::mutex& fftw_planner_mutex() {
  static std::mutex m;
  return m;
}

template <typename T>
T* fftw_array(std::size_t count) {
  void* p = fftwf_malloc(sizeof(T) * count);
  if (!p) throw std::bad_alloc();
  return static_cast<T*>(p);
}

// The cross spectrum conj(A_k) B_k = Im(Z_k Z_-k) / 2 - i (|Z_k|^2 - |Z_-k|^2) / 4 (times `half` =
// 1/2n and `quarter` = 1/4n) on the half spectrum kx = 0 .. nx / 2, from Z (interleaved complex
// values), row by row: Z_-k at kx is the mirror row's (ky, kz negated) kx = 0 for kx = 0, else its
// nx - kx. From kx = 1 on, C values at a time (the mirror's run read backwards); every value gets
// the same float operations in the same order as one at a time, so every build gives the same bits.
template <int C>
struct CrossLanes;  // C complex values: C real or imaginary parts, and the 2 C floats they come in
template <>
struct CrossLanes<4> {
  using Part = float __attribute__((vector_size(16)));
  using Pair = float __attribute__((vector_size(32)));
};
template <>
struct CrossLanes<8> {
  using Part = float __attribute__((vector_size(32)));
  using Pair = float __attribute__((vector_size(64)));
};

template <int C>
[[gnu::always_inline]] inline void cross_spectrum_row(const float* __restrict z, const float* __restrict m, int nx,
                                                      float half, float quarter, float* __restrict out) {
  using Part = typename CrossLanes<C>::Part;
  using Pair = typename CrossLanes<C>::Pair;
  const auto one = [&](int kx, int mx) {
    const float zr = z[2 * kx], zi = z[2 * kx + 1], mr = m[2 * mx], mi = m[2 * mx + 1];
    out[2 * kx] = (zr * mi + zi * mr) * half;
    out[2 * kx + 1] = ((mr * mr + mi * mi) - (zr * zr + zi * zi)) * quarter;
  };
  one(0, 0);
  const int half_x = nx / 2 + 1;
  int kx = 1;
  for (; kx + C <= half_x; kx += C) {
    Pair zv, mv;
    __builtin_memcpy(&zv, z + 2 * kx, sizeof zv);
    __builtin_memcpy(&mv, m + 2 * (nx - kx - C + 1), sizeof mv);  // Z_-k for kx + C - 1 .. kx
    Part zr, zi, mr, mi;
    if constexpr (C == 4) {
      zr = __builtin_shufflevector(zv, zv, 0, 2, 4, 6);
      zi = __builtin_shufflevector(zv, zv, 1, 3, 5, 7);
      mr = __builtin_shufflevector(mv, mv, 6, 4, 2, 0);
      mi = __builtin_shufflevector(mv, mv, 7, 5, 3, 1);
    } else {
      zr = __builtin_shufflevector(zv, zv, 0, 2, 4, 6, 8, 10, 12, 14);
      zi = __builtin_shufflevector(zv, zv, 1, 3, 5, 7, 9, 11, 13, 15);
      mr = __builtin_shufflevector(mv, mv, 14, 12, 10, 8, 6, 4, 2, 0);
      mi = __builtin_shufflevector(mv, mv, 15, 13, 11, 9, 7, 5, 3, 1);
    }
    const Part re = (zr * mi + zi * mr) * half;
    const Part im = ((mr * mr + mi * mi) - (zr * zr + zi * zi)) * quarter;
    Pair o;
    if constexpr (C == 4)
      o = __builtin_shufflevector(re, im, 0, 4, 1, 5, 2, 6, 3, 7);
    else
      o = __builtin_shufflevector(re, im, 0, 8, 1, 9, 2, 10, 3, 11, 4, 12, 5, 13, 6, 14, 7, 15);
    __builtin_memcpy(out + 2 * kx, &o, sizeof o);
  }
  for (; kx < half_x; ++kx) one(kx, nx - kx);
}

template <int C>
[[gnu::always_inline]] inline void cross_spectrum_body(const float* spec, const std::array<int, 3>& s, float half,
                                                       float quarter, float* cross) {
  const std::size_t half_x = std::size_t(s[0] / 2 + 1);
  for (int kz = 0; kz < s[2]; ++kz) {
    const int mz = kz ? s[2] - kz : 0;
    for (int ky = 0; ky < s[1]; ++ky) {
      const int my = ky ? s[1] - ky : 0;
      const std::size_t row = (std::size_t(kz) * s[1] + ky) * s[0], mirror_row = (std::size_t(mz) * s[1] + my) * s[0];
      cross_spectrum_row<C>(spec + 2 * row, spec + 2 * mirror_row, s[0], half, quarter,
                            cross + 2 * (std::size_t(kz) * s[1] + ky) * half_x);
    }
  }
}

__attribute__((target("avx512f"))) void cross_spectrum_avx512(const float* spec, const std::array<int, 3>& s,
                                                              float half, float quarter, float* cross) {
  cross_spectrum_body<8>(spec, s, half, quarter, cross);
}
__attribute__((target("avx2"))) void cross_spectrum_avx2(const float* spec, const std::array<int, 3>& s, float half,
                                                         float quarter, float* cross) {
  cross_spectrum_body<8>(spec, s, half, quarter, cross);
}
void cross_spectrum_baseline(const float* spec, const std::array<int, 3>& s, float half, float quarter, float* cross) {
  cross_spectrum_body<4>(spec, s, half, quarter, cross);
}
void cross_spectrum(const float* spec, const std::array<int, 3>& s, float half, float quarter, float* cross) {
  for_isa(cross_spectrum_avx512, cross_spectrum_avx2, cross_spectrum_baseline)(spec, s, half, quarter, cross);
}

// z = a + i b over n values, interleaved (a copy: the same bits in every build).
[[gnu::always_inline]] inline void interleave_body(const float* __restrict a, const float* __restrict b, std::size_t n,
                                                   float* __restrict z) {
  for (std::size_t i = 0; i < n; ++i) {
    z[2 * i] = a[i];
    z[2 * i + 1] = b[i];
  }
}

__attribute__((target("avx512f"))) void interleave_avx512(const float* a, const float* b, std::size_t n, float* z) {
  interleave_body(a, b, n, z);
}
__attribute__((target("avx2"))) void interleave_avx2(const float* a, const float* b, std::size_t n, float* z) {
  interleave_body(a, b, n, z);
}
void interleave_baseline(const float* a, const float* b, std::size_t n, float* z) { interleave_body(a, b, n, z); }
void interleave(const float* a, const float* b, std::size_t n, float* z) {
  for_isa(interleave_avx512, interleave_avx2, interleave_baseline)(a, b, n, z);
}

}  // namespace

// Aligned buffers from fftwf_malloc, so the plans' alignment assumptions hold for every thread.
struct FftCorrelator::Workspace::Buffers {
  std::size_t real_count;
  float* a;
  float* b;
  fftwf_complex* z;      // a + i b
  fftwf_complex* spec;   // Z = DFT(a + i b)
  fftwf_complex* cross;  // conj(A) B on the half spectrum kx = 0 .. nx / 2 (it is Hermitian)
  float* corr;

  Buffers(std::size_t n, std::size_t n_half)
      : real_count(n),
        a(fftw_array<float>(n)),
        b(fftw_array<float>(n)),
        z(fftw_array<fftwf_complex>(n)),
        spec(fftw_array<fftwf_complex>(n)),
        cross(fftw_array<fftwf_complex>(n_half)),
        corr(fftw_array<float>(n)) {}
  ~Buffers() {
    fftwf_free(a);
    fftwf_free(b);
    fftwf_free(z);
    fftwf_free(spec);
    fftwf_free(cross);
    fftwf_free(corr);
  }
  Buffers(const Buffers&) = delete;
  Buffers& operator=(const Buffers&) = delete;
};

struct FftCorrelator::Plans {
  fftwf_plan forward = nullptr;
  fftwf_plan inverse = nullptr;
  tbb::enumerable_thread_specific<Workspace> workspaces;

  template <typename Init>
  explicit Plans(Init init) : workspaces(init) {}
};

FftCorrelator::Workspace::Workspace(const FftCorrelator& owner, std::unique_ptr<Buffers> buffers)
    : owner_(&owner), buffers_(std::move(buffers)) {}

std::span<float> FftCorrelator::Workspace::window_a() { return {buffers_->a, buffers_->real_count}; }
std::span<float> FftCorrelator::Workspace::window_b() { return {buffers_->b, buffers_->real_count}; }

SpectralWeights::SpectralWeights(std::array<int, 3> shape, double whitening,
                                 const std::array<double, 3>& peak_sigma_voxel)
    : whitening_(float(whitening)) {
  const int half_x = shape[0] / 2 + 1;
  gauss_.resize(std::size_t(shape[2]) * shape[1] * half_x);
  // Frequencies in cycles per voxel, negative ones wrapped as FFTW lays them out.
  const auto frequency = [](int k, int n) { return double(k <= n / 2 ? k : k - n) / n; };
  const double c = 2 * std::numbers::pi * std::numbers::pi;
  std::size_t i = 0;
  for (int kz = 0; kz < shape[2]; ++kz)
    for (int ky = 0; ky < shape[1]; ++ky)
      for (int kx = 0; kx < half_x; ++kx, ++i) {
        const double f[3] = {frequency(kx, shape[0]), frequency(ky, shape[1]), frequency(kz, shape[2])};
        double e = 0;
        for (int a = 0; a < 3; ++a) e += peak_sigma_voxel[a] * peak_sigma_voxel[a] * f[a] * f[a];
        gauss_[i] = float(std::exp(-c * e));
      }
}

namespace {

// C G / |C|^p over `count` interleaved complex values but the first (k = 0, zero after the mean
// subtraction), built once per instruction set below. |C|^p from |C|^2: square roots (exact, so every
// build gives the same bits) for the usual p = 1/2 and 1. Without a branch: |C|^2 below the smallest
// normal float is taken as that float, and C (0 there, or nearly) times the finite scale stays 0.
[[gnu::always_inline]] inline void weigh_cross_spectrum_body(float* __restrict c, const float* __restrict gauss,
                                                             std::size_t count, float p) {
  const auto weigh = [&](auto root) {
    for (std::size_t k = 1; k < count; ++k) {
      const float re = c[2 * k], im = c[2 * k + 1];
      const float scale = gauss[k] / root(std::max(re * re + im * im, std::numeric_limits<float>::min()));
      c[2 * k] = re * scale;
      c[2 * k + 1] = im * scale;
    }
  };
  if (p == 0.5f)
    weigh([](float m) { return std::sqrt(std::sqrt(m)); });
  else if (p == 1.f)
    weigh([](float m) { return std::sqrt(m); });
  else
    weigh([p](float m) { return std::pow(m, 0.5f * p); });
}

__attribute__((target("avx512f"))) void weigh_cross_spectrum_avx512(float* c, const float* gauss, std::size_t count,
                                                                    float p) {
  weigh_cross_spectrum_body(c, gauss, count, p);
}
__attribute__((target("avx2"))) void weigh_cross_spectrum_avx2(float* c, const float* gauss, std::size_t count,
                                                               float p) {
  weigh_cross_spectrum_body(c, gauss, count, p);
}
void weigh_cross_spectrum_baseline(float* c, const float* gauss, std::size_t count, float p) {
  weigh_cross_spectrum_body(c, gauss, count, p);
}
void weigh_cross_spectrum(float* c, const float* gauss, std::size_t count, float p) {
  for_isa(weigh_cross_spectrum_avx512, weigh_cross_spectrum_avx2, weigh_cross_spectrum_baseline)(c, gauss, count, p);
}

}  // namespace

std::span<float> FftCorrelator::Workspace::correlate(const SpectralWeights* weights) {
  Buffers& w = *buffers_;
  const std::size_t n = w.real_count;
  const std::array<int, 3>& s = owner_->shape_;
  // Both windows in one complex transform: Z = DFT(a + i b) = A + i B, with A and B Hermitian,
  // so A_k = (Z_k + conj Z_-k) / 2 and B_k = (Z_k - conj Z_-k) / 2i. One complex transform
  // replaces two real-to-complex ones: FFTW's real transform of a 16^3 window costs about as
  // much as its complex one (docs/lab/2026-11-23.md, "Correlation 1.6x faster").
  interleave(w.a, w.b, n, &w.z[0][0]);
  fftwf_execute_dft(owner_->plans_->forward, w.z, w.spec);
  // conj(A_k) B_k = Im(Z_k Z_-k) / 2 - i (|Z_k|^2 - |Z_-k|^2) / 4, scaled by 1/n so the
  // inverse transform gives the plain correlation sum.
  const float half = 0.5f / float(n), quarter = 0.25f / float(n);
  cross_spectrum(&w.spec[0][0], s, half, quarter, &w.cross[0][0]);
  // Mean subtraction (it removes the pedestal that would otherwise put a broad peak at shift 0)
  // changes only the k = 0 term of A and B: their product there is zero.
  w.cross[0][0] = 0.f;
  w.cross[0][1] = 0.f;
  if (weights)
    weigh_cross_spectrum(&w.cross[0][0], weights->gauss().data(), weights->gauss().size(), weights->whitening());
  fftwf_execute_dft_c2r(owner_->plans_->inverse, w.cross, w.corr);
  return {w.corr, n};
}

FftCorrelator::FftCorrelator(std::array<int, 3> shape, FftPlanning planning) : shape_(shape) {
  const std::size_t n = size();
  const std::size_t n_half = std::size_t(shape[2]) * shape[1] * (shape[0] / 2 + 1);
  plans_ = std::make_unique<Plans>(
      [this, n, n_half] { return Workspace(*this, std::make_unique<Workspace::Buffers>(n, n_half)); });
  Workspace::Buffers probe(n, n_half);
  std::lock_guard lock(fftw_planner_mutex());
  // FFTW takes the slowest-varying dimension first: [z][y][x].
  const unsigned flags = planning == FftPlanning::measure ? FFTW_MEASURE : FFTW_ESTIMATE;
  plans_->forward = fftwf_plan_dft_3d(shape[2], shape[1], shape[0], probe.z, probe.spec, FFTW_FORWARD, flags);
  plans_->inverse = fftwf_plan_dft_c2r_3d(shape[2], shape[1], shape[0], probe.cross, probe.corr, flags);
  if (!plans_->forward || !plans_->inverse) throw std::bad_alloc();
}

FftCorrelator::~FftCorrelator() {
  std::lock_guard lock(fftw_planner_mutex());
  fftwf_destroy_plan(plans_->forward);
  fftwf_destroy_plan(plans_->inverse);
}

const FftCorrelator& FftCorrelator::shared(std::array<int, 3> shape, FftPlanning planning) {
  // The planner mutex must outlive the cache, whose destructors take it: construct it first.
  fftw_planner_mutex();
  static std::mutex m;
  static std::map<std::pair<std::array<int, 3>, FftPlanning>, std::unique_ptr<FftCorrelator>> cache;
  std::lock_guard lock(m);
  auto& slot = cache[{shape, planning}];
  if (!slot) slot = std::make_unique<FftCorrelator>(shape, planning);
  return *slot;
}

FftCorrelator::Workspace& FftCorrelator::workspace() const { return plans_->workspaces.local(); }

}  // namespace plenopiv::piv
