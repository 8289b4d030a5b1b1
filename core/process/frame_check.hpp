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

// A frame's lowest and highest count, gathered a few rows at a time while something else reads
// them (a recorder writing the frame: io::write_tiff's row visitor), so that the check above need
// not read the whole frame again. A frame none of whose pixels were added is empty.
struct FrameRange {
  std::uint16_t min = 0xffff, max = 0;
  bool empty = true;
  void add(std::span<const std::uint16_t> pixels);
};
// frame_problem on a frame whose range is known: the same answer, and the pixels are read again
// only for a frame at full scale (to count its clipped pixels). `range` must hold every pixel.
std::optional<std::string> frame_problem(std::span<const std::uint16_t> pixels, int bit_depth, const FrameRange& range);
// The same for a frame read as float (io::read_raw_frame: PNG, 8/16-bit or float TIFF). Values
// are counts as the file holds them; a float file's values are full scale only if they reach
// 2^k - 1 exactly, so saturation in a float frame of another scale goes unnoticed.
std::optional<std::string> frame_problem(std::span<const float> pixels, int bit_depth = 0);

}  // namespace plenopiv::process
