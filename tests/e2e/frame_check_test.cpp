// process::frame_problem: raw frames with nothing to measure (no light, or clipped) are named, and
// ordinary frames pass, for camera counts and float frames.
#include <gtest/gtest.h>

#include <algorithm>
#include <cstdint>
#include <stdexcept>
#include <string>
#include <vector>

#include "core/process/frame_check.hpp"

namespace plenopiv::process {
namespace {

// An 850 x 850 frame of low counts with `clipped` pixels at `full`.
template <typename T>
std::vector<T> frame(std::size_t clipped, T full) {
  std::vector<T> pixels(850 * 850);
  for (std::size_t i = 0; i < pixels.size(); ++i) pixels[i] = T(i * 7919 % 300);
  for (std::size_t i = 0; i < clipped; ++i) pixels[i * 97 % pixels.size()] = full;
  return pixels;
}

TEST(FrameCheck, NoLightAndClippingAreNamedAndOrdinaryFramesPass) {
  const std::size_t one_percent = 850 * 850 / 100;
  EXPECT_FALSE(frame_problem(std::span<const std::uint16_t>(frame<std::uint16_t>(0, 0))));
  // At most 1 % at full scale passes; more is named with its share and the full scale.
  EXPECT_FALSE(frame_problem(std::span<const std::uint16_t>(frame<std::uint16_t>(one_percent, 65535))));
  const auto clipped = frame_problem(std::span<const std::uint16_t>(frame<std::uint16_t>(2 * one_percent, 65535)));
  ASSERT_TRUE(clipped);
  EXPECT_EQ(clipped->rfind("saturated: 2.00 % of the pixels at full scale 65535", 0), 0u) << *clipped;
  // A 12-bit camera's full scale, given and guessed from the maximum.
  const auto twelve = frame<std::uint16_t>(3 * one_percent, 4095);
  EXPECT_NE(frame_problem(std::span<const std::uint16_t>(twelve), 12)->find("full scale 4095"), std::string::npos);
  EXPECT_NE(frame_problem(std::span<const std::uint16_t>(twelve))->find("full scale 4095"), std::string::npos);
  EXPECT_FALSE(frame_problem(std::span<const std::uint16_t>(twelve), 16));  // 4095 is not a 16-bit camera's full scale
  const std::vector<std::uint16_t> dark(850 * 850, 0);
  EXPECT_EQ(frame_problem(std::span<const std::uint16_t>(dark))->rfind("all zero", 0), 0u);
  // The same for float frames.
  EXPECT_FALSE(frame_problem(std::span<const float>(frame<float>(0, 0.f))));
  EXPECT_NE(frame_problem(std::span<const float>(frame<float>(2 * one_percent, 65535.f)))->find("full scale 65535"),
            std::string::npos);
  const std::vector<float> dark_float(850 * 850, 0.f);
  EXPECT_EQ(frame_problem(std::span<const float>(dark_float))->rfind("all zero", 0), 0u);
  EXPECT_FALSE(frame_problem(std::span<const float>()));
}

// The range a recorder gathers row by row as it writes a frame gives the whole-frame check's answers.
TEST(FrameCheck, ARangeGatheredRowByRowGivesTheSameAnswers) {
  const std::size_t one_percent = 850 * 850 / 100;
  const std::vector<std::vector<std::uint16_t>> frames{
      frame<std::uint16_t>(0, 0), frame<std::uint16_t>(2 * one_percent, 65535),
      frame<std::uint16_t>(3 * one_percent, 4095), std::vector<std::uint16_t>(850 * 850, 0)};
  for (const auto& pixels : frames) {
    FrameRange range;
    for (std::size_t row = 0; row < 850; ++row) range.add(std::span(pixels).subspan(row * 850, 850));
    EXPECT_EQ(range.min, *std::min_element(pixels.begin(), pixels.end()));
    EXPECT_EQ(range.max, *std::max_element(pixels.begin(), pixels.end()));
    for (const int bit_depth : {0, 12, 16}) {
      EXPECT_EQ(frame_problem(std::span<const std::uint16_t>(pixels), bit_depth, range),
                frame_problem(std::span<const std::uint16_t>(pixels), bit_depth));
    }
  }
  // A range that saw none of the frame's pixels is a caller's mistake, not a frame without light.
  EXPECT_THROW(frame_problem(std::span<const std::uint16_t>(frames[0]), 0, FrameRange{}), std::logic_error);
}

}  // namespace
}  // namespace plenopiv::process
