// Raw frames that hold nothing to measure: no light at all, or saturated.
#pragma once

#include <cstdint>
#include <optional>
#include <span>
#include <string>

namespace plenopiv::process {

// What makes a raw frame useless for PIV, or nothing: every pixel zero (no light reached the
// sensor: laser off, lens cap, the camera not triggered), or more than 1 % of the pixels at full
// scale (2^bit_depth - 1; with bit_depth 0, unknown, the frame's maximum when that is 2^k - 1 for k
// in 8..16) so that particle images are clipped and their sub-pixel positions lost. The text names
// the problem and what to check; it does not name the frame.
std::optional<std::string> frame_problem(std::span<const std::uint16_t> pixels, int bit_depth = 0);

}  // namespace plenopiv::process
