// `sim://`: a trigger with no hardware that records every edge with its time, for tests and for
// the simulated camera (which listens to the camera line to know when to make a pair).
#pragma once

#include <functional>
#include <memory>
#include <mutex>
#include <vector>

#include "drivers/common/device_uri.hpp"
#include "drivers/trigger/scheduled_trigger.hpp"

namespace plenopiv::drivers {

struct RecordedEdge {
  TriggerLine line = TriggerLine::Camera;
  bool level = false;
  std::uint64_t shot = 0;
  double planned_s = 0;  // from the start of playback
  double actual_s = 0;   // planned + how late it was written (equal in virtual time)
  // A rising Q-switch edge: the time (ns, the trigger's sync clock) its laser's sync output was
  // stamped with, as report_sync_edge got it; 0 for every other edge.
  std::uint64_t sync_ns = 0;
};

// URI parameters: clock=real|virtual (default real: edges are written at their times on the
// steady clock; virtual: all at once, stamped with their planned times, for fast tests);
// uncertainty_us=<us> (default 0) to stand in for a backend with jitter.
class SimTrigger final : public ScheduledTrigger {
 public:
  SimTrigger(const std::string& uri, bool virtual_clock, double uncertainty_s);
  ~SimTrigger() override;
  void start(std::uint64_t shots) override;

  std::vector<RecordedEdge> edges() const;
  // Current level of each line, indexed by TriggerLine.
  bool level(TriggerLine line) const;
  // The seam for the simulated camera: called on the playback thread for every edge written.
  // Keep it short; set it before start().
  using EdgeListener = std::function<void(const RecordedEdge&)>;
  void set_edge_listener(EdgeListener listener);
  bool connect_camera_input(TriggerInput* input) override;
  // Virtual clock only: how late (ns) edge `edge` of shot `shot` is written, standing in for a
  // playback thread on a busy machine; unset, every edge is on time. Set it before start().
  using DelayModel = std::function<std::int64_t(std::uint64_t shot, std::size_t edge)>;
  void set_virtual_delays(DelayModel model);

 protected:
  void write_line(TriggerLine line, bool level) override;
  void all_low() noexcept override;
  bool virtual_time() const override { return virtual_clock_; }
  void on_edge_written(const Edge& edge, std::uint64_t shot, double planned_s, double lateness_s) override;
  std::int64_t virtual_delay_ns(std::uint64_t shot, std::size_t edge) const override;

 private:
  bool virtual_clock_;
  mutable std::mutex mutex_;
  std::vector<RecordedEdge> edges_;
  bool levels_[6] = {};
  EdgeListener listener_;
  DelayModel delays_;
  TriggerInput* camera_input_ = nullptr;
  std::uint64_t base_ns_ = 1'000'000'000;  // virtual clock origin for Q-switch sync times
};

std::unique_ptr<Trigger> open_sim_trigger(const DeviceUri& uri);

}  // namespace plenopiv::drivers
