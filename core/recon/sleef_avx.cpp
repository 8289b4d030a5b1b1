// SLEEF's deterministic ln and exp eight floats at a time; built with -mavx (CMakeLists.txt), so it
// holds these loops only: no inline function another file could share.
#include <immintrin.h>
#include <sleef.h>

#include "core/recon/sleef_wide.hpp"

namespace plenopiv::recon::kernels {

void log_avx(float* v, std::size_t n) {
  for (std::size_t i = 0; i < n; i += 8) _mm256_storeu_ps(v + i, Sleef_cinz_logf8_u35avx(_mm256_loadu_ps(v + i)));
}

void exp_avx(float* v, std::size_t n) {
  for (std::size_t i = 0; i < n; i += 8) _mm256_storeu_ps(v + i, Sleef_cinz_expf8_u10avx(_mm256_loadu_ps(v + i)));
}

}  // namespace plenopiv::recon::kernels
