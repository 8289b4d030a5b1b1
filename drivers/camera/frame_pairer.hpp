// Pairs frames A and B of each trigger by trigger index, frame id and timestamp gap; pure logic.
#pragma once

#include <cstdint>
#include <deque>
#include <optional>
#include <vector>

#include "drivers/camera/camera.hpp"

namespace plenopiv::drivers {

struct PairerOptions {
  // Frames of one pair are at most this far apart (device clock if both frames have one, else host).
  std::uint64_t max_gap_ns = 50'000'000;
  // 0: frame ids never wrap (64-bit ids). 65536: GigE Vision 16-bit block ids, which wrap from
  // 65535 to 1; id 0 is reserved there and means "unknown" (a frame whose leader was lost).
  std::uint64_t frame_id_modulus = 0;
  // A waiting frame A is given up (host clock) this long after it arrived: its B is not coming.
  // Generous, because host arrival jitters far more than the device's own timestamps.
  std::uint64_t stale_after_ns = 1'000'000'000;
};

// Counts kept by the pairer; see CameraCounters for their meaning.
struct PairerCounts {
  std::uint64_t frames_received = 0;
  std::uint64_t frames_incomplete = 0;
  std::uint64_t frames_lost = 0;
  std::uint64_t frames_discarded = 0;
  std::uint64_t pairs_delivered = 0;
  std::uint64_t pairs_discarded = 0;
};

// Frames go in in arrival order; a pair comes out when frame B arrives next to its frame A.
// Two frames are paired only if their ids are consecutive, they are at most max_gap apart, and,
// when the backend knows trigger indices, they carry the same one. Anything else (a frame whose
// partner is lost, late or incomplete) is discarded and counted, never paired with a wrong frame.
// Invariant: frames_received == 2 * pairs_delivered + frames_discarded + waiting(). A buffer with
// an id already seen (a duplicate or a stale buffer) is not a frame and is not counted.
class FramePairer {
 public:
  explicit FramePairer(PairerOptions options = {});

  // `trigger_index`: when the backend knows which trigger made the frame. Otherwise it is counted
  // from frame ids (frames since the first one, halved).
  std::optional<FramePair> push(Frame frame, std::optional<std::uint64_t> trigger_index = {});
  // A waiting frame that has been waiting longer than stale_after_ns at host time `now_ns` is discarded.
  void expire(std::uint64_t now_host_ns);
  // Discards a waiting frame (stop: its partner will not come).
  void flush();
  // The device restarted its frame ids (reconnect): forget the last id, discard a waiting frame.
  void restart_sequence();

  void set_options(const PairerOptions& options) { options_ = options; }
  const PairerOptions& options() const { return options_; }
  const PairerCounts& counts() const { return counts_; }
  // Discarded pairs with their trigger index, since the last call (at most kMaxDrops kept).
  std::vector<PairDrop> take_drops();
  static constexpr std::size_t kMaxDrops = 4096;
  int waiting() const { return pending_ ? 1 : 0; }

 private:
  struct Pending {
    Frame frame;
    std::optional<std::uint64_t> trigger_index;
    std::uint64_t sequence = 0;
  };
  // Ids between two consecutive frames: 1 = next, 0 = same id, k = k - 1 frames lost.
  std::uint64_t id_distance(std::uint64_t from, std::uint64_t to) const;
  std::uint64_t next_id(std::uint64_t id) const;
  bool within_gap(const Frame& a, const Frame& b) const;
  void discard_pending();
  void record_drop(std::uint64_t trigger_index, PairDrop::Reason reason);
  // A pair of trigger `trigger_index` was delivered: a frame discarded as unpaired under the same
  // trigger (a stray frame before the pair, or a partner that came too late) lost no trigger, and
  // its drop, not taken yet, is withdrawn, so that no trigger is both recorded and listed lost.
  void forget_unpaired_drop(std::uint64_t trigger_index);

  PairerOptions options_;
  PairerCounts counts_;
  std::optional<Pending> pending_;
  std::optional<std::uint64_t> last_id_;
  std::uint64_t sequence_ = 0;  // frames since the first, lost ones included
  std::uint64_t unplaced_ = 0;  // frames with unknown id since the last placed one
  static constexpr std::size_t kRememberMissing = 64;
  std::deque<std::uint64_t> missing_;  // ids counted lost that may still arrive late
  std::deque<PairDrop> drops_;
};

}  // namespace plenopiv::drivers
