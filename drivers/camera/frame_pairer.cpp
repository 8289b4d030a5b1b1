// Pairs frames A and B of each trigger by trigger index, frame id and timestamp gap; pure logic.
#include "drivers/camera/frame_pairer.hpp"

#include <algorithm>
#include <utility>

namespace plenopiv::drivers {

FramePairer::FramePairer(PairerOptions options) : options_(options) {}

std::uint64_t FramePairer::id_distance(std::uint64_t from, std::uint64_t to) const {
  const std::uint64_t m = options_.frame_id_modulus;
  if (m == 0) return to >= from ? to - from : 0;
  std::uint64_t d = ((to % m) + m - (from % m)) % m;
  // GigE Vision skips the reserved id 0 when wrapping: 65535 → 1 is the next frame.
  if (to < from && d > 0) d -= 1;
  return d;
}

std::uint64_t FramePairer::next_id(std::uint64_t id) const {
  const std::uint64_t m = options_.frame_id_modulus;
  if (m == 0) return id + 1;
  return id + 1 >= m ? 1 : id + 1;
}

bool FramePairer::within_gap(const Frame& a, const Frame& b) const {
  const bool device = a.device_timestamp_ns != 0 && b.device_timestamp_ns != 0;
  const std::uint64_t ta = device ? a.device_timestamp_ns : a.host_timestamp_ns;
  const std::uint64_t tb = device ? b.device_timestamp_ns : b.host_timestamp_ns;
  if (tb < ta) return false;  // B before A cannot be its partner
  return tb - ta <= options_.max_gap_ns;
}

void FramePairer::record_drop(std::uint64_t trigger_index, PairDrop::Reason reason) {
  drops_.push_back({trigger_index, reason});
  if (drops_.size() > kMaxDrops) drops_.pop_front();
}

void FramePairer::forget_unpaired_drop(std::uint64_t trigger_index) {
  const auto before = drops_.size();
  std::erase_if(drops_, [&](const PairDrop& d) {
    return d.trigger_index == trigger_index && d.reason == PairDrop::Reason::Unpaired;
  });
  counts_.pairs_discarded -= before - drops_.size();
}

std::vector<PairDrop> FramePairer::take_drops() {
  std::vector<PairDrop> out(drops_.begin(), drops_.end());
  drops_.clear();
  return out;
}

void FramePairer::discard_pending() {
  if (!pending_) return;
  ++counts_.frames_discarded;
  ++counts_.pairs_discarded;
  record_drop(pending_->trigger_index ? *pending_->trigger_index : pending_->sequence / 2,
              pending_->frame.complete ? PairDrop::Reason::Unpaired : PairDrop::Reason::Incomplete);
  pending_.reset();
}

std::optional<FramePair> FramePairer::push(Frame frame, std::optional<std::uint64_t> trigger_index) {
  auto count_arrival = [&] {
    ++counts_.frames_received;
    if (!frame.complete) ++counts_.frames_incomplete;
  };
  if (options_.frame_id_modulus != 0 && frame.frame_id % options_.frame_id_modulus == 0) {
    // Unknown id: it cannot be placed or paired. The gap it leaves is not counted lost.
    count_arrival();
    ++counts_.frames_discarded;
    ++unplaced_;
    return std::nullopt;
  }
  std::uint64_t distance = 1;
  if (last_id_) {
    const bool repeated = frame.frame_id == *last_id_;
    distance = id_distance(*last_id_, frame.frame_id);
    const bool late = !repeated && (options_.frame_id_modulus == 0 ? frame.frame_id < *last_id_
                                                                   : id_distance(frame.frame_id, *last_id_) < distance);
    if (repeated || late) {
      // A frame finished after a later one (e.g. it waited for resent packets) was counted lost
      // when the later one came: now it has arrived, but it cannot be paired. Anything else with
      // an old id is a duplicate or a stale buffer, not a frame: it is ignored.
      auto it = std::find(missing_.begin(), missing_.end(), frame.frame_id);
      if (it == missing_.end()) return std::nullopt;
      missing_.erase(it);
      --counts_.frames_lost;
      count_arrival();
      ++counts_.frames_discarded;
      return std::nullopt;
    }
    const std::uint64_t gap = distance - 1 > unplaced_ ? distance - 1 - unplaced_ : 0;
    counts_.frames_lost += gap;
    // Remember which ids went missing, in case they still come (bounded: a long outage is lost).
    std::uint64_t id = *last_id_;
    for (std::uint64_t k = 0; k < std::min<std::uint64_t>(gap, kRememberMissing); ++k) {
      id = next_id(id);
      missing_.push_back(id);
    }
    while (missing_.size() > kRememberMissing) missing_.pop_front();
    sequence_ += distance;
  }
  count_arrival();
  last_id_ = frame.frame_id;
  unplaced_ = 0;

  if (pending_) {
    const bool partner = distance == 1 && within_gap(pending_->frame, frame) &&
                         (!pending_->trigger_index || !trigger_index || *pending_->trigger_index == *trigger_index);
    if (partner) {
      Pending a = std::move(*pending_);
      pending_.reset();
      if (!a.frame.complete || !frame.complete) {
        counts_.frames_discarded += 2;
        ++counts_.pairs_discarded;
        record_drop(a.trigger_index ? *a.trigger_index : a.sequence / 2, PairDrop::Reason::Incomplete);
        return std::nullopt;
      }
      FramePair pair;
      pair.pair_index = counts_.pairs_delivered++;
      pair.trigger_index = a.trigger_index ? *a.trigger_index : a.sequence / 2;
      forget_unpaired_drop(pair.trigger_index);
      pair.a = std::move(a.frame);
      pair.b = std::move(frame);
      return pair;
    }
    discard_pending();
  }
  pending_ = Pending{std::move(frame), trigger_index, sequence_};
  return std::nullopt;
}

void FramePairer::expire(std::uint64_t now_host_ns) {
  if (pending_ && now_host_ns > pending_->frame.host_timestamp_ns + options_.stale_after_ns) {
    discard_pending();
  }
}

void FramePairer::flush() { discard_pending(); }

void FramePairer::restart_sequence() {
  discard_pending();
  last_id_.reset();
  sequence_ = 0;
  unplaced_ = 0;
  missing_.clear();
}

}  // namespace plenopiv::drivers
