// Attaches the measured laser pulses of each shot to the camera's frame pair of the same trigger.
#pragma once

#include <deque>

#include "drivers/camera/camera.hpp"
#include "drivers/trigger/trigger.hpp"

namespace plenopiv::drivers {

// Both the trigger (shot_index) and the camera (trigger_index) count triggers from their start(),
// so a pair and a shot with the same index belong together. Shots wait here (at most `capacity`)
// until their pair comes; older ones are dropped. Pure; not thread-safe.
class ShotJoiner {
 public:
  explicit ShotJoiner(std::size_t capacity = 256) : capacity_(capacity) {}
  void add_shot(const MeasuredShot& shot) {
    shots_.push_back(shot);
    if (shots_.size() > capacity_) shots_.pop_front();
  }
  // Fills pair.measured when the shot is known; returns whether it was.
  bool attach(FramePair& pair) {
    while (!shots_.empty() && shots_.front().shot_index < pair.trigger_index) shots_.pop_front();
    if (shots_.empty() || shots_.front().shot_index != pair.trigger_index) return false;
    pair.measured = LaserPulses{shots_.front().pulse1_ns, shots_.front().pulse2_ns};
    shots_.pop_front();
    return true;
  }

 private:
  std::size_t capacity_;
  std::deque<MeasuredShot> shots_;
};

}  // namespace plenopiv::drivers
