// Raw frames that hold nothing to measure: no light at all, or saturated.
#include "core/process/frame_check.hpp"

#include <algorithm>
#include <cstdint>
#include <stdexcept>
#include <utility>

#include <opencv2/core.hpp>

namespace plenopiv::process {
namespace {

// The lowest and highest value of a non-empty frame: OpenCV's min/max in chunks whose length fits
// cv::Mat's int sizes.
template <typename T>
std::pair<T, T> range_of(std::span<const T> pixels) {
  double lo = 0, hi = 0;
  constexpr std::size_t kChunk = std::size_t(1) << 30;
  for (std::size_t at = 0; at < pixels.size(); at += kChunk) {
    const std::size_t n = std::min(kChunk, pixels.size() - at);
    const cv::Mat view(1, int(n), cv::DataType<T>::type, const_cast<T*>(pixels.data() + at));
    double chunk_lo = 0, chunk_hi = 0;
    cv::minMaxIdx(view, &chunk_lo, &chunk_hi);
    lo = at ? std::min(lo, chunk_lo) : chunk_lo;
    hi = at ? std::max(hi, chunk_hi) : chunk_hi;
  }
  return {T(lo), T(hi)};
}

// The one check for both pixel types, given the frame's range: a float frame
// (io::read_raw_frame) holds the counts of an 8/16-bit file as they are, so the same full scales
// apply.
template <typename T>
std::optional<std::string> problem_of(std::span<const T> pixels, int bit_depth, T min, T max) {
  if (max == T(0) && min == T(0)) {
    return std::string("all zero: no light reached the sensor (laser, lens cap, camera trigger?)");
  }
  double full = 0;
  if (bit_depth > 0) {
    full = double((1u << std::min(bit_depth, 16)) - 1);
  } else {
    for (int k = 8; k <= 16; ++k) {
      if (double(max) == double((1u << k) - 1)) full = double(max);
    }
  }
  if (full == 0 || double(max) < full) return std::nullopt;
  const auto at_full = std::count_if(pixels.begin(), pixels.end(), [&](T p) { return double(p) >= full; });
  if (double(at_full) <= 0.01 * double(pixels.size())) return std::nullopt;
  return "saturated: " + std::to_string(100.0 * double(at_full) / double(pixels.size())).substr(0, 4) +
         " % of the pixels at full scale " + std::to_string(std::uint32_t(full)) +
         " (lower the laser power, gain or exposure)";
}

template <typename T>
std::optional<std::string> problem_of(std::span<const T> pixels, int bit_depth) {
  if (pixels.empty()) return std::nullopt;
  const auto [min, max] = range_of(pixels);
  return problem_of(pixels, bit_depth, min, max);
}

}  // namespace

void FrameRange::add(std::span<const std::uint16_t> pixels) {
  // Blocks of a fixed length, which the compiler turns into vector min/max without a remainder
  // loop (it leaves a loop of unknown length scalar), then the rest one by one: on rows still in
  // cache this runs far faster than the memory the frame would otherwise be read from again.
  constexpr std::size_t kBlock = 64;
  std::uint16_t lo = min, hi = max;
  std::size_t i = 0;
  for (; i + kBlock <= pixels.size(); i += kBlock) {
    const std::uint16_t* p = pixels.data() + i;
    std::uint16_t block_lo = 0xffff, block_hi = 0;
    for (std::size_t k = 0; k < kBlock; ++k) {
      block_lo = std::min(block_lo, p[k]);
      block_hi = std::max(block_hi, p[k]);
    }
    lo = std::min(lo, block_lo);
    hi = std::max(hi, block_hi);
  }
  for (; i < pixels.size(); ++i) {
    lo = std::min(lo, pixels[i]);
    hi = std::max(hi, pixels[i]);
  }
  min = lo;
  max = hi;
  empty = empty && pixels.empty();
}

std::optional<std::string> frame_problem(std::span<const std::uint16_t> pixels, int bit_depth) {
  return problem_of(pixels, bit_depth);
}

std::optional<std::string> frame_problem(std::span<const std::uint16_t> pixels, int bit_depth,
                                         const FrameRange& range) {
  if (pixels.empty()) return std::nullopt;
  if (range.empty) throw std::logic_error("frame_problem: the frame's range holds none of its pixels");
  return problem_of(pixels, bit_depth, range.min, range.max);
}

std::optional<std::string> frame_problem(std::span<const float> pixels, int bit_depth) {
  return problem_of(pixels, bit_depth);
}

}  // namespace plenopiv::process
