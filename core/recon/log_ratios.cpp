// MART's per-pixel log-ratios (kernels::log_ratios), in a file of its own so that its loop calls
// glibc's vector logarithm (libmvec), which GCC reaches only under -ffast-math (CMakeLists.txt).
#include <cmath>

#include "core/recon/kernels.hpp"

namespace plenopiv::recon::kernels {
namespace {

// One loop without a branch, so that it vectorises: every value is computed for every pixel and
// the pixel's case selects one. ln P of a P below kTiny (only P = 0 in practice: the volume's
// values are 0 or at least kTiny) is taken as ln kTiny; such a P selects 0 or a log-ratio at its
// bound either way.
template <bool Scaled>
void log_ratios_of(const LogRatioInputs& in, std::size_t i0, std::size_t i1, float* __restrict ratio) {
  const float* __restrict projection = in.projection;
  const float* __restrict data = in.data;
  const float* __restrict log_data = in.log_data;
  const float* __restrict white = in.white;
  const float* __restrict scale = in.scale;
  const float max_log = in.max_log, log_floor = in.log_floor, dark_floor = in.dark_floor, tiny = in.tiny;
  for (std::size_t i = i0; i < i1; ++i) {
    const float p = projection[i], k = Scaled ? scale[i] : 1.f;
    const float log_p = logf(std::fmax(p, tiny));
    const float lit = k * std::fmin(std::fmax(log_data[i] - log_p, -max_log), max_log);
    const float dark = k * std::fmax(log_floor - log_p, -max_log);
    const float r = data[i] > 0.f ? (p > 0.f ? lit : 0.f) : (p > dark_floor ? dark : 0.f);
    ratio[i] = white[i] == 0.f ? 0.f : r;
  }
}

}  // namespace

void log_ratios(const LogRatioInputs& in, std::size_t i0, std::size_t i1, float* ratio) {
  if (in.scale)
    log_ratios_of<true>(in, i0, i1, ratio);
  else
    log_ratios_of<false>(in, i0, i1, ratio);
}

}  // namespace plenopiv::recon::kernels
