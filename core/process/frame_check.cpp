// Raw frames that hold nothing to measure: no light at all, or saturated.
#include "core/process/frame_check.hpp"

#include <algorithm>

namespace plenopiv::process {

std::optional<std::string> frame_problem(std::span<const std::uint16_t> pixels, int bit_depth) {
  if (pixels.empty()) return std::nullopt;
  std::uint16_t max = 0;
  for (std::uint16_t p : pixels) max = std::max(max, p);
  if (max == 0) return std::string("all zero: no light reached the sensor (laser, lens cap, camera trigger?)");
  std::uint32_t full = 0;
  if (bit_depth > 0) {
    full = (1u << std::min(bit_depth, 16)) - 1;
  } else {
    for (int k = 8; k <= 16; ++k) {
      if (std::uint32_t(max) == (1u << k) - 1) full = max;
    }
  }
  if (full == 0 || max < full) return std::nullopt;
  const auto at_full = std::count_if(pixels.begin(), pixels.end(), [&](std::uint16_t p) { return p >= full; });
  if (double(at_full) <= 0.01 * double(pixels.size())) return std::nullopt;
  return "saturated: " + std::to_string(100.0 * double(at_full) / double(pixels.size())).substr(0, 4) +
         " % of the pixels at full scale " + std::to_string(full) + " (lower the laser power, gain or exposure)";
}

}  // namespace plenopiv::process
