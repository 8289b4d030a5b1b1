// MART's loops over every pixel or voxel that take a logarithm or an exponential
// (kernels::log_ratios, log_or_zero, log_pixels, multiply_by_exp, extrapolate): the functions through SLEEF, as
// wide as the vectors of isa()'s build, the rest in loops the vectoriser takes (-O3, CMakeLists.txt).
#include <sleef.h>

#include <algorithm>

#include "core/base/isa.hpp"
#include "core/recon/kernels.hpp"
#include "core/recon/sleef_wide.hpp"

namespace plenopiv::recon::kernels {
namespace {

// Values per chunk: a chunk's arguments and results stay in L1.
constexpr std::size_t kChunkValues = 256;

// The widest vectors of SLEEF's functions the kernels' build (isa()) runs: an AVX2 CPU has AVX.
enum class Width { sse2 = 4, avx = 8, avx512 = 16 };
Width widest() {
  switch (isa()) {
    case Isa::avx512:
      return Width::avx512;
    case Isa::avx2:
      return Width::avx;
    case Isa::baseline:
      break;
  }
  return Width::sse2;
}

// ln and exp of n values (n <= kChunkValues), as many at a time as the CPU's widest vectors hold:
// SLEEF's deterministic functions ("cinz": no fused multiply-add; ln within 3.5 ulp, exp within 1
// ulp), which give the same bits in every width (tests/recon/vector_math_test.cpp), so every
// x86-64 CPU gives the same bits. A chunk's last few values are padded (with 1) to a whole vector,
// so that every value goes through the same function wherever a range starts or ends.
std::size_t padded(float* v, std::size_t n, Width w) {
  const std::size_t lanes = std::size_t(w);
  for (std::size_t i = n; i % lanes; ++i) v[i] = 1.f;
  return (n + lanes - 1) / lanes * lanes;
}
// One of SLEEF's functions in every width: the AVX and AVX-512 loops (sleef_wide.hpp) and the SSE2
// vector function.
struct SleefFunction {
  void (*avx512)(float*, std::size_t);
  void (*avx)(float*, std::size_t);
  __m128 (*sse2)(__m128);
};
void apply_n(const SleefFunction& f, float* v, std::size_t n) {
  const Width w = widest();
  n = padded(v, n, w);
  if (w == Width::avx512) return f.avx512(v, n);
  if (w == Width::avx) return f.avx(v, n);
  for (std::size_t i = 0; i < n; i += 4) _mm_storeu_ps(v + i, f.sse2(_mm_loadu_ps(v + i)));
}
void log_n(float* v, std::size_t n) {
  apply_n({log_avx512, log_avx, [](__m128 x) { return Sleef_cinz_logf4_u35sse2(x); }}, v, n);
}
void exp_n(float* v, std::size_t n) {
  apply_n({exp_avx512, exp_avx, [](__m128 x) { return Sleef_cinz_expf4_u10sse2(x); }}, v, n);
}

// Runs chunk(first value, count) over [i0, i1) in chunks of kChunkValues.
template <typename Chunk>
void in_chunks(std::size_t i0, std::size_t i1, Chunk&& chunk) {
  for (std::size_t i = i0; i < i1; i += kChunkValues) chunk(i, std::min(kChunkValues, i1 - i));
}

// Every case is computed for every pixel and the pixel's case selects one (no branch, so the loop
// vectorises). ln P of a P below `tiny` (only P = 0 in practice: the volume's values are 0 or at
// least kTiny) is taken as ln tiny; such a P selects 0 or a log-ratio at its bound either way.
// `ratio` may be the projection itself: a chunk's P is copied before any ratio is written.
template <bool Scaled>
void log_ratios_of(const LogRatioInputs& in, std::size_t i0, std::size_t i1, float* ratio) {
  const float max_log = in.max_log, log_floor = in.log_floor, dark_floor = in.dark_floor, tiny = in.tiny;
  in_chunks(i0, i1, [&](std::size_t c, std::size_t n) {
    alignas(16) float p[kChunkValues], log_p[kChunkValues];
    std::copy_n(in.projection + c, n, p);
    for (std::size_t j = 0; j < n; ++j) log_p[j] = std::max(p[j], tiny);
    log_n(log_p, n);
    const float* __restrict data = in.data + c;
    const float* __restrict log_data = in.log_data + c;
    const float* __restrict white = in.white + c;
    const float* __restrict scale = Scaled ? in.scale + c : nullptr;
    float* out = ratio + c;
    for (std::size_t j = 0; j < n; ++j) {
      float lit = log_data[j] - log_p[j], dark = log_floor - log_p[j];
      lit = lit < -max_log ? -max_log : (lit > max_log ? max_log : lit);
      dark = dark < -max_log ? -max_log : dark;
      if constexpr (Scaled) {
        lit *= scale[j];
        dark *= scale[j];
      }
      const float pj = p[j];
      const float lit_or_0 = pj > 0.f ? lit : 0.f, dark_or_0 = pj > dark_floor ? dark : 0.f;
      const float r = data[j] > 0.f ? lit_or_0 : dark_or_0;
      out[j] = white[j] == 0.f ? 0.f : r;
    }
  });
}

}  // namespace

void log_ratios(const LogRatioInputs& in, std::size_t i0, std::size_t i1, float* ratio) {
  if (in.scale)
    log_ratios_of<true>(in, i0, i1, ratio);
  else
    log_ratios_of<false>(in, i0, i1, ratio);
}

void log_or_zero(const float* values, std::size_t i0, std::size_t i1, float* out) {
  in_chunks(i0, i1, [&](std::size_t c, std::size_t n) {
    alignas(16) float ln[kChunkValues];
    const float* __restrict v = values + c;
    for (std::size_t j = 0; j < n; ++j) ln[j] = v[j] > 0.f ? v[j] : 1.f;
    log_n(ln, n);
    for (std::size_t j = 0; j < n; ++j) out[c + j] = v[j] > 0.f ? ln[j] : 0.f;
  });
}

void log_pixels(const float* data, const float* white, float log_floor, float tiny, std::size_t i0, std::size_t i1,
                float* out) {
  in_chunks(i0, i1, [&](std::size_t c, std::size_t n) {
    alignas(16) float ln[kChunkValues];
    const float* __restrict d = data + c;
    for (std::size_t j = 0; j < n; ++j) ln[j] = std::max(d[j], tiny);
    log_n(ln, n);
    const float* __restrict w = white + c;
    for (std::size_t j = 0; j < n; ++j) out[c + j] = (d[j] > 0.f ? ln[j] : log_floor) * w[j];
  });
}

void multiply_by_exp(const MultiplicativeUpdate& u, std::size_t i0, std::size_t i1) {
  const float mu = u.mu, max_log = u.max_log, tiny = u.tiny, huge = u.huge;
  in_chunks(i0, i1, [&](std::size_t c, std::size_t n) {
    alignas(16) float grow[kChunkValues];
    const float* __restrict update = u.update + c;
    for (std::size_t j = 0; j < n; ++j) {
      const float x = mu * update[j];
      grow[j] = x < -max_log ? -max_log : (x > max_log ? max_log : x);
    }
    exp_n(grow, n);
    float* __restrict e = u.e + c;
    for (std::size_t j = 0; j < n; ++j) {
      const float y = e[j] * grow[j];
      e[j] = y < tiny ? 0.f : (y > huge ? huge : y);
    }
  });
}

void extrapolate(const Extrapolation& x, std::size_t i0, std::size_t i1) {
  const float beta = x.beta, max_log = x.max_log, tiny = x.tiny, huge = x.huge;
  in_chunks(i0, i1, [&](std::size_t c, std::size_t n) {
    // A value is 0 or at least `tiny`: ln max(v, tiny) is ln v wherever v > 0 selects it.
    alignas(16) float ln[kChunkValues], grow[kChunkValues];
    float* __restrict e = x.e + c;
    float* __restrict last = x.last + c;
    float* __restrict log_last = x.log_last + c;
    float* __restrict momentum = x.momentum + c;
    for (std::size_t j = 0; j < n; ++j) ln[j] = std::max(e[j], tiny);
    log_n(ln, n);
    for (std::size_t j = 0; j < n; ++j) {
      const float v = e[j];
      const float log_v = v > 0.f ? ln[j] : 0.f, change = log_v - log_last[j];
      const float step = last[j] > 0.f ? change : 0.f;
      momentum[j] = v > 0.f ? step : 0.f;
      last[j] = v;
      log_last[j] = log_v;
      const float b = beta * momentum[j];
      grow[j] = b < -max_log ? -max_log : (b > max_log ? max_log : b);
    }
    exp_n(grow, n);
    for (std::size_t j = 0; j < n; ++j) {
      const float y = e[j] * grow[j];
      e[j] = y < tiny ? 0.f : (y > huge ? huge : y);
    }
  });
}

}  // namespace plenopiv::recon::kernels
