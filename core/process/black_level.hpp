// A raw frame's black level (the sensor's pedestal, its dark signal and any background light),
// measured per tile on the pixels between the microlens images and taken off before MART.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include "core/base/image.hpp"

namespace plenopiv::process {

// What is taken off each raw frame before the reconstruction (config key
// `reconstruction.black_level`):
//   between_images (default): each frame's median count over the pixels between the microlens
//     images, tile by tile over the sensor (BlackLevelMeter). No ray through the main lens's
//     aperture reaches them, so what they record is the sensor's pedestal and dark signal and light
//     scattered in the camera: what MART would otherwise take for particle light in every voxel. A
//     frame whose pixels there read 0 (a simulation counting one per ray) is reconstructed as
//     recorded.
//   none: frames are reconstructed as recorded (frames already dark-subtracted).
enum class BlackLevel { between_images, none };
inline constexpr std::array<std::string_view, 2> kBlackLevelNames{"between_images", "none"};
std::string_view name_of(BlackLevel level);
// InputError naming `what` (the key or option) and the names when `name` is none of them.
BlackLevel black_level_named(std::string_view name, std::string_view what);

// A frame's black level, counts, per tile of the raw sensor: tile (i, j) holds the raw pixels
// x in [i W / tiles_x, (i + 1) W / tiles_x), and likewise y. Empty (nothing to take off) where
// none was measured.
struct BlackLevels {
  int width = 0, height = 0;  // the raw sensor, px
  int tiles_x = 0, tiles_y = 0;
  std::vector<float> level;  // row-major over the tiles

  // One level over a whole width x height sensor (a frame dark-subtracted by hand, a test).
  static BlackLevels uniform(int width, int height, float level);
  bool measured() const { return !level.empty(); }
  // Unmeasured, or 0 in every tile: subtracting changes no pixel.
  bool nothing() const { return lowest() == 0.f && highest() == 0.f; }
  // The median of the tiles' levels (the one number status lines report), their lowest and
  // highest; 0 when unmeasured.
  float median() const;
  float lowest() const;
  float highest() const;
  // "20", or "20 (19 to 51 over 10 x 6 tiles)" where the tiles differ; "0" when unmeasured.
  std::string text() const;
};

// Where a frame's black level is read: sensor pixels whose calibrated white correction is 0 and
// whose eight neighbours' are too (outside every lens's image disk and not beside one, where a
// particle's image blurred by diffraction reaches), at most kMaxSamples of them spread evenly over
// the sensor. The level is each tile's own median, so that a sensor read out through two or four
// taps with different offsets (halves or quadrants: the tile counts are even), or with a dark
// signal that varies across it, is taken off where it is. Tiles are about kTilePx on a side, fewer
// and larger where one would hold fewer than kMinSamples such pixels (the whole sensor as one
// tile at the coarsest). Fewer than kMinSamples on the whole sensor (micro-images that touch, or a
// white correction without zeros): none are kept and measure() gives no level.
class BlackLevelMeter {
 public:
  static constexpr std::size_t kMaxSamples = std::size_t(1) << 16;
  static constexpr std::size_t kMinSamples = 256;
  static constexpr int kTilePx = 512;

  BlackLevelMeter() = default;
  // `white`: the calibrated white correction of the raw sensor (calib::LoadedCalibration's).
  explicit BlackLevelMeter(const ImageF& white);

  // The sampled pixels; 0 when the white leaves too few.
  std::size_t samples() const { return pixels_.size(); }
  // The pixels the white leaves between the images, sampled or not (what samples() was drawn from).
  std::size_t candidates() const { return candidates_; }
  int tiles_x() const { return tiles_x_; }
  int tiles_y() const { return tiles_y_; }
  // The frame's median count over each tile's sampled pixels; unmeasured without samples. `frame`
  // must be finite (PairProcessor validates frames first); one of another size than the white is
  // an InputError.
  BlackLevels measure(const ImageF& frame) const;
  BlackLevels measure(const ImageU16& frame) const;
  // One line for the user: how the black level is measured, or why it is not.
  std::string describe() const;

 private:
  void check_size(int width, int height) const;
  template <typename T>
  BlackLevels measure_counts(const T* frame) const;

  int width_ = 0, height_ = 0;
  int tiles_x_ = 0, tiles_y_ = 0;
  std::size_t candidates_ = 0;
  std::vector<std::uint32_t> pixels_;    // row-major indices, tile by tile, increasing in each
  std::vector<std::size_t> tile_start_;  // tile t's samples: pixels_[tile_start_[t], tile_start_[t + 1])
};

// `frame` minus its tile's level, at least 0, in place; nothing when `levels` is unmeasured.
// `frame` is the raw sensor or its pixels binned k x k (bin_pixels: each binned pixel takes the
// level of its block's first raw pixel); another size is an InputError.
void subtract_black_level(ImageF& frame, const BlackLevels& levels);

}  // namespace plenopiv::process
