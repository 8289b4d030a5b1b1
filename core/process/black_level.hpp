// A raw frame's black level (the sensor's pedestal, its dark signal and any background light),
// measured on the pixels between the microlens images and taken off the frame before MART.
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
//     images (BlackLevelMeter). No ray through the main lens's aperture reaches them, so what they
//     record is the sensor's pedestal and dark signal and light scattered in the camera or the
//     flow: what MART would otherwise take for particle light in every voxel. A frame whose
//     pixels there read 0 (a simulation counting one per ray) is reconstructed as recorded.
//   none: frames are reconstructed as recorded (frames already dark-subtracted).
enum class BlackLevel { between_images, none };
inline constexpr std::array<std::string_view, 2> kBlackLevelNames{"between_images", "none"};
std::string_view name_of(BlackLevel level);
// InputError naming `what` (the key or option) and the names when `name` is none of them.
BlackLevel black_level_named(std::string_view name, std::string_view what);

// Where a frame's black level is read: sensor pixels whose calibrated white correction is 0 and
// whose eight neighbours' are too (outside every lens's image disk and not beside one, where a
// particle's image blurred by diffraction reaches), at most kMaxSamples of them spread evenly over
// the sensor. Fewer than kMinSamples such pixels (micro-images that touch, or a white correction
// without zeros): none are kept and measure() is 0.
class BlackLevelMeter {
 public:
  static constexpr std::size_t kMaxSamples = std::size_t(1) << 16;
  static constexpr std::size_t kMinSamples = 256;

  BlackLevelMeter() = default;
  // `white`: the calibrated white correction of the raw sensor (calib::LoadedCalibration's).
  explicit BlackLevelMeter(const ImageF& white);

  // The sampled pixels; 0 when the white leaves too few.
  std::size_t samples() const { return pixels_.size(); }
  // The pixels the white leaves between the images, sampled or not (what samples() was drawn from).
  std::size_t candidates() const { return candidates_; }
  // The frame's median count over the sampled pixels; 0 without samples. `frame` must be finite
  // (PairProcessor validates frames first); one of another size than the white is an InputError.
  float measure(const ImageF& frame) const;
  float measure(const ImageU16& frame) const;
  // One line for the user: how the black level is measured, or why it is not.
  std::string describe() const;

 private:
  void check_size(int width, int height) const;

  int width_ = 0, height_ = 0;
  std::size_t candidates_ = 0;
  std::vector<std::uint32_t> pixels_;  // row-major indices, increasing
};

// `frame` minus `level` counts, at least 0, in place; nothing when `level` is 0.
void subtract_black_level(ImageF& frame, float level);

}  // namespace plenopiv::process
