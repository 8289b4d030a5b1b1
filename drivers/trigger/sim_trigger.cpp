// `sim://`: a trigger with no hardware that records every edge with its time, for tests and for
// the simulated camera (which listens to the camera line to know when to make a pair).
#include "drivers/trigger/sim_trigger.hpp"

#include "core/base/errors.hpp"
#include "drivers/common/driver_errors.hpp"

namespace plenopiv::drivers {

SimTrigger::SimTrigger(const std::string& uri, bool virtual_clock, double uncertainty_s)
    : ScheduledTrigger(
          TriggerInfo{uri, "sim", uncertainty_s, {kTriggerLines.begin(), kTriggerLines.end()}, true, true}),
      virtual_clock_(virtual_clock) {}

SimTrigger::~SimTrigger() { stop_playback(); }

void SimTrigger::start(std::uint64_t shots) {
  if (virtual_clock_ && shots == 0) {
    throw InputError("trigger " + info().uri + ": a virtual clock needs a shot count (start(n))");
  }
  {
    std::lock_guard lock(mutex_);
    edges_.clear();
  }
  ScheduledTrigger::start(shots);
}

void SimTrigger::write_line(TriggerLine line, bool level) {
  std::lock_guard lock(mutex_);
  levels_[int(line)] = level;
}

void SimTrigger::all_low() noexcept {
  std::lock_guard lock(mutex_);
  for (bool& l : levels_) l = false;
}

void SimTrigger::on_edge_written(const Edge& edge, std::uint64_t shot, double planned_s, double lateness_s) {
  RecordedEdge r{edge.line, edge.rising, shot, planned_s, planned_s + lateness_s};
  // The laser's Q-switch sync output fires with each Q-switch: measure it like gpiod would.
  const bool laser_fired = edge.rising && (edge.line == TriggerLine::QSwitch1 || edge.line == TriggerLine::QSwitch2);
  if (laser_fired) r.sync_ns = virtual_clock_ ? base_ns_ + std::uint64_t(r.actual_s * 1e9) : now_ns();
  EdgeListener listener;
  TriggerInput* camera_input = nullptr;
  {
    std::lock_guard lock(mutex_);
    edges_.push_back(r);
    listener = listener_;
    camera_input = camera_input_;
  }
  // The camera line, wired to a simulated camera's trigger input.
  if (camera_input && edge.line == TriggerLine::Camera && edge.rising) camera_input->rising_edge();
  if (laser_fired) {
    report_sync_edge(r.sync_ns);
    // The simulated scene moves between the pulses that really fired (a late Q-switch 1 shortens dt).
    if (camera_input) camera_input->laser_pulse(r.sync_ns);
  }
  if (listener) listener(r);
}

std::vector<RecordedEdge> SimTrigger::edges() const {
  std::lock_guard lock(mutex_);
  return edges_;
}

bool SimTrigger::level(TriggerLine line) const {
  std::lock_guard lock(mutex_);
  return levels_[int(line)];
}

void SimTrigger::set_edge_listener(EdgeListener listener) {
  std::lock_guard lock(mutex_);
  listener_ = std::move(listener);
}

void SimTrigger::set_virtual_delays(DelayModel model) {
  if (running()) throw StateError("trigger " + info().uri + ": set_virtual_delays while running");
  std::lock_guard lock(mutex_);
  delays_ = std::move(model);
}

std::int64_t SimTrigger::virtual_delay_ns(std::uint64_t shot, std::size_t edge) const {
  std::lock_guard lock(mutex_);
  return delays_ ? delays_(shot, edge) : 0;
}

bool SimTrigger::connect_camera_input(TriggerInput* input) {
  if (running()) throw StateError("trigger " + info().uri + ": connect_camera_input while running");
  std::lock_guard lock(mutex_);
  camera_input_ = input;
  return true;
}

std::unique_ptr<Trigger> open_sim_trigger(const DeviceUri& uri) {
  uri.reject_unknown({"clock", "uncertainty_us"});
  const std::string clock = uri.string_or("clock", "real");
  if (clock != "real" && clock != "virtual") uri.fail("clock must be real or virtual, got '" + clock + "'");
  const double uncertainty_us = uri.number_or("uncertainty_us", 0.0);
  if (uncertainty_us < 0) uri.fail("uncertainty_us must be >= 0");
  return std::make_unique<SimTrigger>(uri.text(), clock == "virtual", uncertainty_us * 1e-6);
}

}  // namespace plenopiv::drivers
