// SLEEF's deterministic ln and exp sixteen floats at a time; built with -mavx512f (CMakeLists.txt),
// so it holds these loops only: no inline function another file could share.
#include <immintrin.h>
#include <sleef.h>

#include "core/recon/sleef_wide.hpp"

namespace plenopiv::recon::kernels {

void log_avx512(float* v, std::size_t n) {
  for (std::size_t i = 0; i < n; i += 16)
    _mm512_storeu_ps(v + i, Sleef_cinz_logf16_u35avx512fnofma(_mm512_loadu_ps(v + i)));
}

void exp_avx512(float* v, std::size_t n) {
  for (std::size_t i = 0; i < n; i += 16)
    _mm512_storeu_ps(v + i, Sleef_cinz_expf16_u10avx512fnofma(_mm512_loadu_ps(v + i)));
}

}  // namespace plenopiv::recon::kernels
