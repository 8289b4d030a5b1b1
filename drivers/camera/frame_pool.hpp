// Frame buffers reused from pair to pair (areaDetector's NDArrayPool), so that a camera at a steady
// rate fills warm memory instead of a fresh allocation per frame (page faults, a zero fill).
#pragma once

#include <cstddef>
#include <cstdint>
#include <deque>
#include <memory>
#include <mutex>
#include <optional>

#include "core/base/image.hpp"
#include "drivers/camera/camera.hpp"

namespace plenopiv::drivers {

// Thread-safe: a camera's thread takes, whichever consumer drops a frame last gives back.
class FramePool {
 public:
  // Buffers not in use are kept up to `max_spare` of them; further ones given back are freed.
  explicit FramePool(std::size_t max_spare = kDefaultMaxSpare);

  // A spare width x height buffer for the next frame, its pixels whatever a previous frame left (the
  // caller overwrites every one); nullopt when none fits (the caller allocates as it would without
  // a pool, e.g. by copying its source).
  std::optional<ImageU16> reuse(int width, int height);
  // reuse(), or a fresh zeroed image when no spare fits.
  ImageU16 take(int width, int height);
  // A copy of `source` for the next frame: into a spare buffer when one fits, else a plain copy (no
  // zero fill first).
  ImageU16 copy(const ImageU16& source);
  // Adds fresh width x height buffers (their memory touched now) until max_spare are waiting: for a
  // camera's start, so that its first frames fault no memory in while the recording and lanes start.
  void prefill(int width, int height);
  // Keeps the image's buffer for a later take(); beyond max_spare the oldest spare is freed.
  void give(ImageU16 image);

  struct Counts {
    std::uint64_t taken = 0;   // frames asked for (reuse() or take())
    std::uint64_t reused = 0;  // of which had a spare buffer
    std::size_t spare = 0;     // buffers waiting now
  };
  Counts counts() const;

  // Four pairs' frames: enough for a camera that delivers at the rate a recorder writes, without
  // holding much memory when none is needed (a spare is a whole frame: 32 MB at the paper's scale).
  static constexpr std::size_t kDefaultMaxSpare = 8;

 private:
  mutable std::mutex mutex_;
  std::deque<ImageU16> spare_;  // oldest first
  std::size_t max_spare_;
  Counts counts_;
};

// A delivered pair shared among its consumers (recorder, lanes, preview); when the last one lets
// go, its frames' buffers go back to `pool` (none: they are freed).
std::shared_ptr<const FramePair> share_pair(FramePair pair, std::shared_ptr<FramePool> pool);

}  // namespace plenopiv::drivers
