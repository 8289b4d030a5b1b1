// The pixels between the microlens images, a frame's median count over them, and its subtraction.
#include "core/process/black_level.hpp"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>

#include "core/base/enum_names.hpp"
#include "core/base/errors.hpp"

namespace plenopiv::process {

std::string_view name_of(BlackLevel level) { return name_in(kBlackLevelNames, level); }

BlackLevel black_level_named(std::string_view name, std::string_view what) {
  return value_named<BlackLevel>(kBlackLevelNames, name, what);
}

namespace {

// Whether (x, y) and its eight neighbours, all on the sensor, have a white correction of 0.
bool between_images(const ImageF& white, int x, int y) {
  if (x < 1 || y < 1 || x + 1 >= white.width || y + 1 >= white.height) return false;
  for (int dy = -1; dy <= 1; ++dy)
    for (int dx = -1; dx <= 1; ++dx)
      if (white.at(x + dx, y + dy) != 0.f) return false;
  return true;
}

template <typename T>
float median_at(const std::vector<std::uint32_t>& pixels, const T* frame) {
  std::vector<float> values(pixels.size());
  for (std::size_t i = 0; i < pixels.size(); ++i) values[i] = float(frame[pixels[i]]);
  const auto middle = values.begin() + std::ptrdiff_t(values.size() / 2);
  std::nth_element(values.begin(), middle, values.end());
  return *middle;
}

}  // namespace

BlackLevelMeter::BlackLevelMeter(const ImageF& white) : width_(white.width), height_(white.height) {
  for (int y = 0; y < white.height; ++y)
    for (int x = 0; x < white.width; ++x) candidates_ += between_images(white, x, y);
  if (candidates_ < kMinSamples) return;
  const std::size_t stride = (candidates_ + kMaxSamples - 1) / kMaxSamples;
  pixels_.reserve(candidates_ / stride + 1);
  std::size_t seen = 0;
  for (int y = 0; y < white.height; ++y)
    for (int x = 0; x < white.width; ++x)
      if (between_images(white, x, y) && seen++ % stride == 0)
        pixels_.push_back(std::uint32_t(std::size_t(y) * std::size_t(white.width) + std::size_t(x)));
}

void BlackLevelMeter::check_size(int width, int height) const {
  if (width != width_ || height != height_)
    throw InputError("black level: the frame is " + std::to_string(width) + " x " + std::to_string(height) +
                     " px, the white correction " + std::to_string(width_) + " x " + std::to_string(height_));
}

float BlackLevelMeter::measure(const ImageF& frame) const {
  if (pixels_.empty()) return 0.f;
  check_size(frame.width, frame.height);
  return median_at(pixels_, frame.pixels.data());
}

float BlackLevelMeter::measure(const ImageU16& frame) const {
  if (pixels_.empty()) return 0.f;
  check_size(frame.width, frame.height);
  return median_at(pixels_, frame.pixels.data());
}

std::string BlackLevelMeter::describe() const {
  if (!pixels_.empty())
    return "black level: each frame's median over " + std::to_string(pixels_.size()) + " of the " +
           std::to_string(candidates_) + " pixels between the microlens images, taken off the frame";
  return "black level: not measured, frames reconstructed as recorded: the white correction leaves " +
         std::to_string(candidates_) + " pixels between the microlens images (at least " + std::to_string(kMinSamples) +
         " needed); dark-subtract the frames or set reconstruction.black_level: none";
}

void subtract_black_level(ImageF& frame, float level) {
  if (level == 0.f) return;
  float* p = frame.pixels.data();
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, frame.pixels.size(), std::size_t(1) << 16),
                    [&](const tbb::blocked_range<std::size_t>& r) {
                      for (std::size_t i = r.begin(); i != r.end(); ++i) p[i] = std::max(0.f, p[i] - level);
                    });
}

}  // namespace plenopiv::process
