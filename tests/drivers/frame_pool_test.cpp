// The frame pool: buffers given back are reused for frames of their size, spares are bounded, and
// a shared pair gives its frames back when its last consumer lets go.
#include <gtest/gtest.h>

#include <thread>
#include <vector>

#include "drivers/camera/frame_pool.hpp"

namespace plenopiv::drivers {
namespace {

TEST(FramePool, ABufferGivenBackIsTheNextFrameOfItsSize) {
  FramePool pool;
  ImageU16 first = pool.take(64, 32);
  EXPECT_EQ(first.width, 64);
  EXPECT_EQ(first.height, 32);
  ASSERT_EQ(first.pixels.size(), 64u * 32u);
  const std::uint16_t* buffer = first.pixels.data();
  pool.give(std::move(first));
  EXPECT_EQ(pool.counts().spare, 1u);

  const ImageU16 other_size = pool.take(32, 64);  // same pixel count, another shape: not reused
  EXPECT_NE(other_size.pixels.data(), buffer);
  const ImageU16 again = pool.take(64, 32);
  EXPECT_EQ(again.pixels.data(), buffer);
  EXPECT_EQ(again.pixels.size(), 64u * 32u);
  const FramePool::Counts c = pool.counts();
  EXPECT_EQ(c.taken, 3u);
  EXPECT_EQ(c.reused, 1u);
  EXPECT_EQ(c.spare, 0u);
}

TEST(FramePool, SparesAreBoundedAndTheOldestGoesFirst) {
  FramePool pool(2);
  std::vector<ImageU16> frames;
  for (int i = 0; i < 3; ++i) frames.push_back(pool.take(16, 16));
  const std::uint16_t* oldest = frames[0].pixels.data();
  for (ImageU16& f : frames) pool.give(std::move(f));
  EXPECT_EQ(pool.counts().spare, 2u);
  for (int i = 0; i < 2; ++i) EXPECT_NE(pool.take(16, 16).pixels.data(), oldest);
  EXPECT_EQ(pool.counts().reused, 2u);
  pool.give(ImageU16{});  // an empty image (a frame moved from) is not a buffer
  EXPECT_EQ(pool.counts().spare, 0u);
}

TEST(FramePool, ACopyFillsASpareBufferOrIsAPlainCopy) {
  FramePool pool;
  ImageU16 source(5, 3);
  for (std::size_t i = 0; i < source.size(); ++i) source.pixels[i] = std::uint16_t(7 * i + 1);
  const ImageU16 plain = pool.copy(source);
  EXPECT_EQ(plain.pixels, source.pixels);
  ImageU16 spare(5, 3, 9);
  const std::uint16_t* buffer = spare.pixels.data();
  pool.give(std::move(spare));
  const ImageU16 pooled = pool.copy(source);
  EXPECT_EQ(pooled.pixels.data(), buffer);
  EXPECT_EQ(pooled.pixels, source.pixels) << "nothing of the spare's old pixels";
  EXPECT_EQ(pooled.width, 5);
  EXPECT_EQ(pool.counts().reused, 1u);
}

TEST(FramePool, APrefillLeavesItsBoundOfSpareBuffersOfTheFramesToCome) {
  FramePool pool(3);
  pool.give(ImageU16(4, 4));
  pool.prefill(16, 8);
  EXPECT_EQ(pool.counts().spare, 3u);
  EXPECT_TRUE(pool.reuse(16, 8).has_value());
  EXPECT_TRUE(pool.reuse(16, 8).has_value());
  EXPECT_FALSE(pool.reuse(16, 8).has_value()) << "one spare was the 4 x 4 given before";
}

TEST(FramePool, ASharedPairGivesItsFramesBackWhenTheLastConsumerLetsGo) {
  auto pool = std::make_shared<FramePool>();
  FramePair pair;
  pair.a.image = pool->take(8, 8);
  pair.b.image = pool->take(8, 8);
  const std::uint16_t* a = pair.a.image.pixels.data();
  const std::uint16_t* b = pair.b.image.pixels.data();
  std::shared_ptr<const FramePair> recorder = share_pair(std::move(pair), pool);
  std::shared_ptr<const FramePair> lane = recorder;
  recorder.reset();
  EXPECT_EQ(pool->counts().spare, 0u) << "a consumer still holds the pair";
  EXPECT_EQ(lane->a.image.pixels.data(), a);
  std::thread([held = std::move(lane)]() mutable { held.reset(); }).join();  // the last, on another thread
  EXPECT_EQ(pool->counts().spare, 2u);
  const ImageU16 next_a = pool->take(8, 8);
  const ImageU16 next_b = pool->take(8, 8);
  EXPECT_TRUE((next_a.pixels.data() == a && next_b.pixels.data() == b) ||
              (next_a.pixels.data() == b && next_b.pixels.data() == a));

  // Without a pool the pair is shared all the same.
  FramePair plain;
  plain.a.image = ImageU16(4, 4, 7);
  EXPECT_EQ(share_pair(std::move(plain), nullptr)->a.image.at(3, 3), 7);
}

}  // namespace
}  // namespace plenopiv::drivers
