// The pixels between the microlens images, a frame's median count over them, and its subtraction.
#include "core/process/black_level.hpp"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <cstdio>

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

// The (upper) median of `values`, which it reorders; not empty.
float median_of(std::vector<float>& values) {
  const auto middle = values.begin() + std::ptrdiff_t(values.size() / 2);
  std::nth_element(values.begin(), middle, values.end());
  return *middle;
}

// The median of the counts at `pixels`.
template <typename T>
float median_at(const std::uint32_t* pixels, std::size_t count, const T* frame) {
  std::vector<float> values(count);
  for (std::size_t i = 0; i < count; ++i) values[i] = float(frame[pixels[i]]);
  return median_of(values);
}

// Which of `tiles` equal parts of [0, extent) raw pixel `position` lies in.
int tile_along(std::int64_t position, int extent, int tiles) { return int(position * tiles / extent); }

// The tile of raw pixel (x, y) on a width x height sensor cut into tiles_x x tiles_y, row-major.
std::size_t tile_of(int x, int y, int width, int height, int tiles_x, int tiles_y) {
  return std::size_t(tile_along(y, height, tiles_y)) * std::size_t(tiles_x) +
         std::size_t(tile_along(x, width, tiles_x));
}

// The even tile count closest to `extent` / BlackLevelMeter::kTilePx, at least 2.
int even_tiles(int extent) {
  return 2 * std::max(1, int(std::lround(double(extent) / (2.0 * BlackLevelMeter::kTilePx))));
}

}  // namespace

BlackLevels BlackLevels::uniform(int width, int height, float level) {
  BlackLevels b;
  b.width = width;
  b.height = height;
  b.tiles_x = b.tiles_y = 1;
  b.level = {level};
  return b;
}

float BlackLevels::median() const {
  if (level.empty()) return 0.f;
  std::vector<float> v = level;
  return median_of(v);
}

float BlackLevels::lowest() const { return level.empty() ? 0.f : *std::min_element(level.begin(), level.end()); }

float BlackLevels::highest() const { return level.empty() ? 0.f : *std::max_element(level.begin(), level.end()); }

std::string BlackLevels::text() const {
  const auto number = [](float v) {
    char b[32];
    std::snprintf(b, sizeof b, "%g", double(v));
    return std::string(b);
  };
  if (lowest() == highest()) return number(median());
  return number(median()) + " (" + number(lowest()) + " to " + number(highest()) + " over " + std::to_string(tiles_x) +
         " x " + std::to_string(tiles_y) + " tiles)";
}

BlackLevelMeter::BlackLevelMeter(const ImageF& white) : width_(white.width), height_(white.height) {
  std::vector<std::uint32_t> candidates;
  for (int y = 0; y < white.height; ++y)
    for (int x = 0; x < white.width; ++x)
      if (between_images(white, x, y))
        candidates.push_back(std::uint32_t(std::size_t(y) * std::size_t(white.width) + std::size_t(x)));
  candidates_ = candidates.size();
  if (candidates_ < kMinSamples) return;
  // The finest grid of even tile counts (about kTilePx on a side) whose every tile holds
  // kMinSamples candidates, coarser grids after it, the whole sensor last.
  const std::size_t stride = (candidates_ + kMaxSamples - 1) / kMaxSamples;
  std::vector<std::size_t> count;
  const auto fits = [&](int tx, int ty) {
    count.assign(std::size_t(tx) * std::size_t(ty), 0);
    for (std::size_t k = 0; k < candidates.size(); k += stride) {
      const std::uint32_t p = candidates[k];
      ++count[tile_of(int(p % std::uint32_t(width_)), int(p / std::uint32_t(width_)), width_, height_, tx, ty)];
    }
    return *std::min_element(count.begin(), count.end()) >= kMinSamples;
  };
  tiles_x_ = even_tiles(width_);
  tiles_y_ = even_tiles(height_);
  while (!fits(tiles_x_, tiles_y_)) {
    if (tiles_x_ == 1 && tiles_y_ == 1) break;  // the whole sensor: kMinSamples, checked above
    if (tiles_x_ == 2 && tiles_y_ == 2) {
      tiles_x_ = tiles_y_ = 1;
    } else {
      tiles_x_ = std::max(2, 2 * (tiles_x_ / 4));
      tiles_y_ = std::max(2, 2 * (tiles_y_ / 4));
    }
  }
  // Each tile's samples together, in row-major order within it (count holds the grid's counts).
  tile_start_.assign(count.size() + 1, 0);
  for (std::size_t t = 0; t < count.size(); ++t) tile_start_[t + 1] = tile_start_[t] + count[t];
  pixels_.resize(tile_start_.back());
  std::vector<std::size_t> next(tile_start_.begin(), tile_start_.end() - 1);
  for (std::size_t k = 0; k < candidates.size(); k += stride) {
    const std::uint32_t p = candidates[k];
    pixels_[next[tile_of(int(p % std::uint32_t(width_)), int(p / std::uint32_t(width_)), width_, height_, tiles_x_,
                         tiles_y_)]++] = p;
  }
}

void BlackLevelMeter::check_size(int width, int height) const {
  if (width != width_ || height != height_)
    throw InputError("black level: the frame is " + std::to_string(width) + " x " + std::to_string(height) +
                     " px, the white correction " + std::to_string(width_) + " x " + std::to_string(height_));
}

template <typename T>
BlackLevels BlackLevelMeter::measure_counts(const T* frame) const {
  BlackLevels b;
  b.width = width_;
  b.height = height_;
  b.tiles_x = tiles_x_;
  b.tiles_y = tiles_y_;
  b.level.resize(tile_start_.size() - 1);
  for (std::size_t t = 0; t + 1 < tile_start_.size(); ++t)
    b.level[t] = median_at(pixels_.data() + tile_start_[t], tile_start_[t + 1] - tile_start_[t], frame);
  return b;
}

BlackLevels BlackLevelMeter::measure(const ImageF& frame) const {
  if (pixels_.empty()) return {};
  check_size(frame.width, frame.height);
  return measure_counts(frame.pixels.data());
}

BlackLevels BlackLevelMeter::measure(const ImageU16& frame) const {
  if (pixels_.empty()) return {};
  check_size(frame.width, frame.height);
  return measure_counts(frame.pixels.data());
}

std::string BlackLevelMeter::describe() const {
  if (!pixels_.empty())
    return "black level: each frame's median over " + std::to_string(pixels_.size()) + " of the " +
           std::to_string(candidates_) + " pixels between the microlens images, in each of " +
           std::to_string(tiles_x_) + " x " + std::to_string(tiles_y_) + " tiles of the sensor, taken off there";
  return "black level: not measured, frames reconstructed as recorded: the white correction leaves " +
         std::to_string(candidates_) + " pixels between the microlens images (at least " + std::to_string(kMinSamples) +
         " needed); dark-subtract the frames or set reconstruction.black_level: none";
}

void subtract_black_level(ImageF& frame, const BlackLevels& levels) {
  if (!levels.measured()) return;
  const int k = frame.width > 0 ? levels.width / frame.width : 0;
  if (k < 1 || frame.width * k != levels.width || frame.height * k != levels.height)
    throw InputError("black level: the frame is " + std::to_string(frame.width) + " x " + std::to_string(frame.height) +
                     " px, neither the sensor's " + std::to_string(levels.width) + " x " +
                     std::to_string(levels.height) + " nor its pixels binned");
  if (levels.nothing()) return;
  // Tile column i holds the binned columns [first[i], first[i + 1]): those whose block's first raw
  // pixel lies in it.
  std::vector<int> first(std::size_t(levels.tiles_x) + 1, frame.width);
  for (int x = frame.width - 1; x >= 0; --x)
    first[std::size_t(tile_along(std::int64_t(x) * k, levels.width, levels.tiles_x))] = x;
  for (int i = levels.tiles_x - 1; i >= 0; --i)  // a tile narrower than a block holds none
    first[std::size_t(i)] = std::min(first[std::size_t(i)], first[std::size_t(i) + 1]);
  float* p = frame.pixels.data();
  tbb::parallel_for(tbb::blocked_range<int>(0, frame.height, 16), [&](const tbb::blocked_range<int>& r) {
    for (int y = r.begin(); y != r.end(); ++y) {
      const float* row_levels =
          levels.level.data() +
          std::size_t(tile_along(std::int64_t(y) * k, levels.height, levels.tiles_y)) * std::size_t(levels.tiles_x);
      float* row = p + std::size_t(y) * std::size_t(frame.width);
      for (int i = 0; i < levels.tiles_x; ++i) {
        const float level = row_levels[i];
        for (int x = first[std::size_t(i)]; x < first[std::size_t(i) + 1]; ++x) row[x] = std::max(0.f, row[x] - level);
      }
    }
  });
}

}  // namespace plenopiv::process
