// The trigger driver interface: plays a Schedule on output lines, reports measured laser pulses.
#pragma once

#include <chrono>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "drivers/camera/camera.hpp"
#include "drivers/trigger/sequencer.hpp"

namespace plenopiv::drivers {

struct TriggerInfo {
  std::string uri;
  std::string backend;               // "sim", "gpiod"
  double timing_uncertainty_s = 0;   // how precisely it places an edge (jitter)
  std::vector<TriggerLine> outputs;  // lines wired
  bool measures_qswitch = false;     // an input line on the laser's Q-switch sync
  bool simulated = false;            // no hardware: its lines reach only simulated devices
};

// The laser pulses of one shot as measured on the Q-switch sync input (kernel timestamps,
// CLOCK_MONOTONIC for gpiod, or the sim trigger's clock). dt_s() is the dt that really happened.
struct MeasuredShot {
  std::uint64_t shot_index = 0;
  std::uint64_t pulse1_ns = 0;
  std::uint64_t pulse2_ns = 0;
  double dt_s() const { return double(pulse2_ns - pulse1_ns) * 1e-9; }
};

struct TriggerCounters {
  std::uint64_t shots_fired = 0;  // shots whose every edge was written
  // Shots played later than planned because the playback had written the previous one late and a
  // laser line would otherwise have risen sooner after its previous rising edge than the laser
  // allows. They still fire, whole, with their own timing.
  std::uint64_t shots_delayed = 0;
  // Shots given up half way for the same reason (a defence that delaying should leave idle; lines
  // already high went low at once).
  std::uint64_t shots_abandoned = 0;
  std::uint64_t edges_written = 0;
  std::uint64_t edges_late = 0;  // written later than the backend's uncertainty
  double worst_lateness_s = 0;
  std::uint64_t sync_edges = 0;     // Q-switch sync edges measured
  std::uint64_t sync_unpaired = 0;  // sync edges that did not make a (pulse 1, pulse 2) shot
};

// Thread safety: load/start/stop from one controlling thread; next_shot, counters and running
// from any. Every backend keeps its output lines low whenever it is not playing a schedule, and
// drives them all low on stop(), on any error, and in its destructor. No laser line (every line
// but the camera's) rises sooner than Schedule::min_laser_interval_ns after its previous rising
// edge, in this run or the one before it in the same process.
class Trigger {
 public:
  virtual ~Trigger() = default;
  virtual TriggerInfo info() const = 0;
  // Checks the schedule (check_schedule: integer times, the laser's minimum interval), that it only
  // uses wired lines and that its margins exceed this backend's timing uncertainty; InputError
  // otherwise. Not while running.
  virtual void load(const Schedule& schedule) = 0;
  // Plays the loaded schedule `shots` times (0: until stop()).
  virtual void start(std::uint64_t shots = 0) = 0;
  virtual void stop() = 0;  // all lines low; a no-op when not running
  virtual bool running() const = 0;
  // Waits for the next measured shot; nullopt on timeout or when nothing measures the Q-switch.
  virtual std::optional<MeasuredShot> next_shot(std::chrono::milliseconds timeout) = 0;
  virtual TriggerCounters counters() const = 0;
  // Connects the camera line to a simulated camera's trigger input (null disconnects); every
  // rising camera edge is then delivered to it. Only a simulated trigger can: a hardware
  // backend's camera line is a physical output and this returns false. Not while running; the
  // input must outlive the connection (disconnect, stop or destroy the trigger first).
  virtual bool connect_camera_input(TriggerInput*) { return false; }
};

}  // namespace plenopiv::drivers
