// Frame buffers reused from pair to pair: the pool and the shared pair that gives its frames back.
#include "drivers/camera/frame_pool.hpp"

#include <algorithm>
#include <new>
#include <utility>

namespace plenopiv::drivers {

FramePool::FramePool(std::size_t max_spare) : max_spare_(max_spare) {}

std::optional<ImageU16> FramePool::reuse(int width, int height) {
  std::lock_guard lock(mutex_);
  ++counts_.taken;
  const auto fits = std::find_if(spare_.begin(), spare_.end(),
                                 [&](const ImageU16& image) { return image.width == width && image.height == height; });
  if (fits == spare_.end()) return std::nullopt;
  ImageU16 image = std::move(*fits);
  spare_.erase(fits);
  ++counts_.reused;
  counts_.spare = spare_.size();
  return image;
}

ImageU16 FramePool::take(int width, int height) {
  if (std::optional<ImageU16> spare = reuse(width, height)) return std::move(*spare);
  return ImageU16(width, height);  // a first frame's allocation and zero fill
}

ImageU16 FramePool::copy(const ImageU16& source) {
  std::optional<ImageU16> image = reuse(source.width, source.height);
  if (!image) return source;
  std::copy(source.pixels.begin(), source.pixels.end(), image->pixels.begin());
  return std::move(*image);
}

void FramePool::prefill(int width, int height) {
  for (;;) {
    {
      std::lock_guard lock(mutex_);
      if (spare_.size() >= max_spare_) return;
    }
    give(ImageU16(width, height));  // zero-filled: every page faulted in here
  }
}

void FramePool::give(ImageU16 image) {
  if (image.empty()) return;
  std::lock_guard lock(mutex_);
  spare_.push_back(std::move(image));
  // The oldest spare goes: after a change of size (a new ROI) it is the one that no longer fits.
  while (spare_.size() > max_spare_) spare_.pop_front();
  counts_.spare = spare_.size();
}

FramePool::Counts FramePool::counts() const {
  std::lock_guard lock(mutex_);
  return counts_;
}

std::shared_ptr<const FramePair> share_pair(FramePair pair, std::shared_ptr<FramePool> pool) {
  if (!pool) return std::make_shared<const FramePair>(std::move(pair));
  return std::shared_ptr<const FramePair>(new FramePair(std::move(pair)), [pool](const FramePair* shared) {
    // The deleter owns the pair it was made with: taking its frames back before deleting it is safe.
    auto* owned = const_cast<FramePair*>(shared);
    try {
      pool->give(std::move(owned->a.image));
      pool->give(std::move(owned->b.image));
    } catch (const std::bad_alloc&) {
      // No room to keep a spare: the buffers are freed with the pair, as without a pool.
    }
    delete owned;
  });
}

}  // namespace plenopiv::drivers
