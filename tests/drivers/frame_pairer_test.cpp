// Frame pairing: consecutive ids within the gap pair; lost, late and incomplete frames never pair.
#include <gtest/gtest.h>

#include <random>

#include "drivers/camera/frame_pairer.hpp"

namespace plenopiv::drivers {
namespace {

constexpr std::uint64_t kMs = 1'000'000;

// Frame `k` (0 = A, 1 = B) of trigger `t`: pairs 100 ms apart, A and B 1 ms apart.
Frame frame(std::uint64_t id, std::uint64_t t, int k, bool complete = true) {
  Frame f;
  f.frame_id = id;
  f.device_timestamp_ns = 1000 * kMs + t * 100 * kMs + std::uint64_t(k) * kMs;
  f.host_timestamp_ns = f.device_timestamp_ns;
  f.complete = complete;
  f.image = ImageU16(2, 2, std::uint16_t(t));  // truth: the trigger that made it
  return f;
}

PairerOptions options(std::uint64_t modulus = 0) { return {10 * kMs, modulus, 1000 * kMs}; }

void expect_invariant(const FramePairer& p) {
  const PairerCounts& c = p.counts();
  EXPECT_EQ(c.frames_received, 2 * c.pairs_delivered + c.frames_discarded + p.waiting());
}

TEST(FramePairer, PairsConsecutiveFramesAndCountsTriggers) {
  FramePairer p(options());
  std::uint64_t id = 10;
  for (std::uint64_t t = 0; t < 4; ++t) {
    EXPECT_FALSE(p.push(frame(id++, t, 0)));
    auto pair = p.push(frame(id++, t, 1));
    ASSERT_TRUE(pair);
    EXPECT_EQ(pair->pair_index, t);
    EXPECT_EQ(pair->trigger_index, t);
    EXPECT_EQ(pair->a.frame_id + 1, pair->b.frame_id);
  }
  EXPECT_EQ(p.counts().pairs_delivered, 4u);
  EXPECT_EQ(p.counts().frames_lost, 0u);
  expect_invariant(p);
}

TEST(FramePairer, LostFrameBDiscardsItsA) {
  FramePairer p(options());
  p.push(frame(1, 0, 0));
  // frame 2 (B of trigger 0) lost
  EXPECT_FALSE(p.push(frame(3, 1, 0)));
  auto pair = p.push(frame(4, 1, 1));
  ASSERT_TRUE(pair);
  EXPECT_EQ(pair->trigger_index, 1u);  // counted from ids, the lost frame included
  EXPECT_EQ(p.counts().frames_lost, 1u);
  EXPECT_EQ(p.counts().pairs_discarded, 1u);
  EXPECT_EQ(p.counts().frames_discarded, 1u);
  expect_invariant(p);
}

TEST(FramePairer, LostFrameAMakesBAnOrphanByTimestampGap) {
  FramePairer p(options());
  p.push(frame(1, 0, 0));
  ASSERT_TRUE(p.push(frame(2, 0, 1)));
  // frame 3 (A of trigger 1) lost; B of trigger 1 must not pair with A of trigger 2
  EXPECT_FALSE(p.push(frame(4, 1, 1)));
  EXPECT_FALSE(p.push(frame(5, 2, 0)));
  auto pair = p.push(frame(6, 2, 1));
  ASSERT_TRUE(pair);
  EXPECT_EQ(pair->a.image.at(0, 0), 2);
  EXPECT_EQ(pair->b.image.at(0, 0), 2);
  EXPECT_EQ(p.counts().frames_lost, 1u);
  EXPECT_EQ(p.counts().pairs_discarded, 1u);
  expect_invariant(p);
}

TEST(FramePairer, IncompleteFrameDiscardsTheWholePair) {
  FramePairer p(options());
  p.push(frame(1, 0, 0));
  EXPECT_FALSE(p.push(frame(2, 0, 1, false)));
  EXPECT_FALSE(p.push(frame(3, 1, 0, false)));
  EXPECT_FALSE(p.push(frame(4, 1, 1)));
  EXPECT_TRUE(p.push(frame(5, 2, 0)) == std::nullopt);
  EXPECT_TRUE(p.push(frame(6, 2, 1)));
  EXPECT_EQ(p.counts().frames_incomplete, 2u);
  EXPECT_EQ(p.counts().pairs_discarded, 2u);
  EXPECT_EQ(p.counts().frames_discarded, 4u);
  expect_invariant(p);
}

TEST(FramePairer, FramesTooFarApartDoNotPair) {
  FramePairer p(options());
  Frame a = frame(1, 0, 0), b = frame(2, 0, 1);
  b.device_timestamp_ns = a.device_timestamp_ns + 11 * kMs;
  p.push(std::move(a));
  EXPECT_FALSE(p.push(std::move(b)));
  // Without device timestamps the host's are used.
  Frame c = frame(3, 1, 0), d = frame(4, 1, 1);
  c.device_timestamp_ns = 0;
  EXPECT_FALSE(p.push(std::move(c)));
  EXPECT_TRUE(p.push(std::move(d)));
}

// A stray frame just before a run's first pair (a camera's leftover, or a frame made before the
// first trigger) is discarded, but its trigger is the pair's: it is not listed lost as well.
TEST(FramePairer, AStrayFrameIsNotListedAsTheLossOfThePairAfterIt) {
  FramePairer p(options());
  Frame stray = frame(1, 0, 0);
  stray.device_timestamp_ns -= 50 * kMs;
  stray.host_timestamp_ns = stray.device_timestamp_ns;
  EXPECT_FALSE(p.push(std::move(stray)));
  EXPECT_FALSE(p.push(frame(2, 0, 0)));  // too late for the stray: it is discarded
  const auto pair = p.push(frame(3, 0, 1));
  ASSERT_TRUE(pair);
  EXPECT_EQ(pair->trigger_index, 0u);
  EXPECT_TRUE(p.take_drops().empty()) << "trigger 0 is recorded: not lost";
  EXPECT_EQ(p.counts().frames_discarded, 1u);
  EXPECT_EQ(p.counts().pairs_discarded, 0u);
  expect_invariant(p);
  // A lost B still lists its trigger: the next pair is another trigger's.
  p.push(frame(4, 1, 0));
  ASSERT_TRUE(p.push(frame(6, 2, 0)) == std::nullopt);  // frame 5 (B of trigger 1) lost
  ASSERT_TRUE(p.push(frame(7, 2, 1)));
  const auto drops = p.take_drops();
  ASSERT_EQ(drops.size(), 1u);
  EXPECT_EQ(drops[0].trigger_index, 1u);
}

TEST(FramePairer, KnownTriggerIndicesMustAgree) {
  FramePairer p(options());
  p.push(frame(1, 0, 0), 7);
  EXPECT_FALSE(p.push(frame(2, 0, 1), 8));
  p.push(frame(3, 1, 0), 9);
  auto pair = p.push(frame(4, 1, 1), 9);
  ASSERT_TRUE(pair);
  EXPECT_EQ(pair->trigger_index, 9u);
}

TEST(FramePairer, GigEVisionIdsWrapFrom65535To1) {
  FramePairer p(options(65536));
  p.push(frame(65534, 0, 0));
  ASSERT_TRUE(p.push(frame(65535, 0, 1)));
  p.push(frame(1, 1, 0));
  ASSERT_TRUE(p.push(frame(2, 1, 1)));
  EXPECT_EQ(p.counts().frames_lost, 0u);
  // Across the wrap, frame 65535 lost: one frame lost, not 65535.
  FramePairer q(options(65536));
  q.push(frame(65533, 0, 0));
  ASSERT_TRUE(q.push(frame(65534, 0, 1)));
  q.push(frame(1, 1, 1));
  EXPECT_EQ(q.counts().frames_lost, 1u);
  // Id 0 is GigE Vision's "unknown": such a frame is discarded, and not counted lost twice.
  FramePairer z(options(65536));
  z.push(frame(65534, 3, 0));
  EXPECT_FALSE(z.push(frame(0, 3, 1, false)));
  z.push(frame(1, 4, 0));
  EXPECT_TRUE(z.push(frame(2, 4, 1)));
  EXPECT_EQ(z.counts().frames_lost, 0u);  // the unknown frame was 65535
  EXPECT_EQ(z.counts().frames_received, 4u);
  expect_invariant(z);
}

TEST(FramePairer, AFrameArrivingAfterALaterOneIsDiscardedNotCountedLost) {
  for (std::uint64_t modulus : {std::uint64_t(0), std::uint64_t(65536)}) {
    FramePairer p(options(modulus));
    p.push(frame(1, 0, 0));
    ASSERT_TRUE(p.push(frame(2, 0, 1)));
    p.push(frame(4, 1, 1));  // 3 seems lost...
    EXPECT_EQ(p.counts().frames_lost, 1u);
    EXPECT_FALSE(p.push(frame(3, 1, 0)));  // ...and comes late
    EXPECT_EQ(p.counts().frames_lost, 0u);
    p.push(frame(5, 2, 0));
    EXPECT_TRUE(p.push(frame(6, 2, 1)));
    EXPECT_EQ(p.counts().frames_received, 6u);
    // The same id again, or an old one never counted lost: a duplicate or stale buffer, ignored.
    EXPECT_FALSE(p.push(frame(3, 1, 0)));
    EXPECT_FALSE(p.push(frame(6, 2, 1)));
    EXPECT_FALSE(p.push(frame(1, 0, 0)));
    EXPECT_EQ(p.counts().frames_received, 6u);
    EXPECT_EQ(p.counts().frames_lost, 0u);
    expect_invariant(p);
  }
}

TEST(FramePairer, StaleAAndFlushAreDiscarded) {
  FramePairer p(options());
  Frame a = frame(1, 0, 0);
  const std::uint64_t t = a.host_timestamp_ns;
  p.push(std::move(a));
  p.expire(t + 500 * kMs);
  EXPECT_EQ(p.waiting(), 1);
  p.expire(t + 1001 * kMs);
  EXPECT_EQ(p.waiting(), 0);
  p.push(frame(3, 1, 0));
  p.flush();
  EXPECT_EQ(p.counts().pairs_discarded, 2u);
  expect_invariant(p);
}

// Random losses and incomplete frames: every pair delivered holds frames of one trigger, in order,
// and every frame is accounted for.
TEST(FramePairer, NeverMismatchesUnderRandomFaults) {
  for (unsigned seed = 1; seed <= 20; ++seed) {
    std::mt19937 rng(seed);
    std::uniform_real_distribution<double> u(0, 1);
    FramePairer p(options(65536));
    std::uint64_t id = 65000, arrived = 0, lost = 0;
    for (std::uint64_t t = 0; t < 500; ++t) {
      for (int k = 0; k < 2; ++k) {
        const std::uint64_t this_id = id;
        id = id == 65535 ? 1 : id + 1;
        if (t > 0 && u(rng) < 0.1) {  // the first frame arrives: trigger 0 anchors the count
          ++lost;
          continue;
        }
        ++arrived;
        auto pair = p.push(frame(this_id, t, k, u(rng) > 0.05));
        if (!pair) continue;
        EXPECT_EQ(pair->a.image.at(0, 0), pair->b.image.at(0, 0)) << "seed " << seed;
        EXPECT_LT(pair->a.device_timestamp_ns, pair->b.device_timestamp_ns);
        EXPECT_EQ(pair->trigger_index, std::uint64_t(pair->a.image.at(0, 0)));
      }
    }
    p.flush();
    EXPECT_EQ(p.counts().frames_received, arrived);
    // Losses after the last arrived frame cannot be seen by ids.
    EXPECT_LE(p.counts().frames_lost, lost);
    EXPECT_GE(p.counts().frames_lost + 2, lost);
    expect_invariant(p);
  }
}

}  // namespace
}  // namespace plenopiv::drivers
