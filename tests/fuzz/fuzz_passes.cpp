// Fuzz target: the --passes mini-language of `plenopiv correlate` (core/piv parse_passes):
// accepted passes satisfy the correlation's own checks.
#include "core/piv/settings.hpp"
#include "tests/fuzz/fuzz_support.hpp"

using namespace plenopiv;

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  std::vector<piv::PassSettings> passes;
  try {
    passes = piv::parse_passes(fuzzing::as_text(data, size));
  } catch (const InputError& e) {
    fuzzing::require_names(e, "--passes");
    return 0;
  }
  fuzzing::require(!passes.empty(), "no pass accepted as passes");
  for (const piv::PassSettings& p : passes) {
    for (int w : p.window) fuzzing::require(w >= 4, "a window below 4 voxels accepted");
    fuzzing::require(p.overlap_percent >= 0 && p.overlap_percent < 100, "an overlap outside [0, 100) accepted");
    fuzzing::require(p.depth_margin >= 0 && p.depth_margin <= p.window[2], "a depth margin beyond the window accepted");
  }
  piv::CorrelationSettings s;
  s.passes = passes;
  piv::check(s, "passes again");
  return 0;
}
