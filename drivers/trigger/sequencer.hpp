// Turns PIV timing (rate, dt, flashlamp-to-Q-switch delay, camera timing) into a schedule of line
// edges for both laser cavities and the camera, refusing schedules that break a constraint. Pure.
#pragma once

#include <array>
#include <cstdint>
#include <string>
#include <vector>

namespace plenopiv::drivers {

// The output lines of a PIV timing unit: two laser cavities (flashlamp, Q-switch) and the camera;
// in hardware-timed mode only Gate, the external delay generator's trigger input.
enum class TriggerLine { Flashlamp1, QSwitch1, Flashlamp2, QSwitch2, Camera, Gate };
constexpr std::array<TriggerLine, 6> kTriggerLines{TriggerLine::Flashlamp1, TriggerLine::QSwitch1,
                                                   TriggerLine::Flashlamp2, TriggerLine::QSwitch2,
                                                   TriggerLine::Camera,     TriggerLine::Gate};
// "flashlamp1", "qswitch1", "flashlamp2", "qswitch2", "camera", "gate" (the gpiod URI keys).
const char* to_string(TriggerLine line);

// What the experiment asks for. Seconds throughout.
struct TimingRequest {
  double repetition_rate_hz = 10.0;        // double pulses (= frame pairs) per second
  double pulse_separation_s = 100e-6;      // dt: laser pulse 1 to laser pulse 2
  double flashlamp_to_qswitch_s = 180e-6;  // the laser's optimum delay, about 150-200 us
  double camera_pretrigger_s = 10e-6;      // camera trigger edge this long before pulse 1
  double exposure_a_s = 20e-6;             // frame A: from the camera trigger to the transfer
  double flashlamp_pulse_width_s = 10e-6;
  double qswitch_pulse_width_s = 10e-6;
  double camera_pulse_width_s = 10e-6;
};

// What the devices allow.
struct TimingLimits {
  double laser_max_rate_hz = 15.0;             // per cavity
  double min_flashlamp_to_qswitch_s = 100e-6;  // the laser's usable Q-switch delay window
  double max_flashlamp_to_qswitch_s = 250e-6;
  double interline_transfer_s = 5e-6;  // camera: end of frame A to start of frame B
  double frame_b_s = 0.05;             // camera: how long frame B collects light
  double camera_max_pair_rate_hz = 15.0;
};

// The laser lines: each fires a cavity (or, for Gate, the delay generator that fires the laser),
// so no two of their rising edges may come closer than the laser's minimum period.
bool is_laser_line(TriggerLine line);

struct Edge {
  std::int64_t time_ns = 0;  // from the start of the period: what the trigger plays
  double time_s = 0;         // the same time in seconds (time_ns * 1e-9), for reports
  TriggerLine line = TriggerLine::Camera;
  bool rising = true;
  bool operator==(const Edge&) const = default;
};

// The longest repetition period a schedule may have (the lowest rate is one pair an hour): keeps
// every time the trigger computes, shot count times period, far inside 64-bit nanoseconds.
inline constexpr std::int64_t kMaxPeriodNs = 3600'000'000'000;

// One period of the timing, repeated every `period_ns`. Times are relative to the first edge
// (t = 0). The integer nanoseconds are what a trigger plays and what check_schedule() checks; the
// seconds beside them are the same times for reports.
struct Schedule {
  std::vector<Edge> edges;  // sorted by time
  std::int64_t period_ns = 0;
  // The shortest time the laser allows between two rising edges of one laser line (1 / its
  // maximum repetition rate, rounded up). Triggers never write a laser edge sooner than that after
  // the same line's previous one, however late their thread runs.
  std::int64_t min_laser_interval_ns = 0;
  double period_s = 0;
  double pulse1_s = 0;         // Q-switch 1 (laser pulse 1)
  double pulse2_s = 0;         // Q-switch 2 (laser pulse 2)
  double frame_a_end_s = 0;    // the interline transfer starts
  double frame_b_start_s = 0;  // the transfer is done
  double frame_b_end_s = 0;
  double smallest_margin_s = 0;      // the tightest constraint's slack...
  std::string smallest_margin_what;  // ...and which one it is
  double dt_s() const { return pulse2_s - pulse1_s; }
};

// Builds the schedule. Throws InputError naming the violated constraint and the parameter to
// change: dt shorter than the interline transfer, pulse 2 outside frame B, pulse 1 outside frame A,
// rate above the laser's or the camera's, a Q-switch delay outside the laser's window, edges that
// overlap. `timing_uncertainty_s` is the trigger backend's jitter: a schedule whose smallest
// margin is below it is refused, pointing to hardware-timed mode.
Schedule make_schedule(const TimingRequest& request, const TimingLimits& limits, double timing_uncertainty_s,
                       const std::string& backend = "this trigger");

// Checks a schedule as a trigger will play it, in integer nanoseconds: a period within
// (0, kMaxPeriodNs] and not shorter than min_laser_interval_ns (> 0), edges sorted inside one
// period, and on every line alternating rising and falling edges that start rising and end low
// within the period, one rising edge per period on each laser line. InputError naming what is
// wrong. make_schedule and make_gate_schedule call it; Trigger::load calls it again, so a schedule
// built any other way is held to the same rules.
void check_schedule(const Schedule& schedule);

// Hardware-timed mode: an external delay generator makes the laser and camera pulses from its own
// clock; plenopiv only gates the shot train with one Gate pulse per shot, so the backend's jitter
// only moves whole shots. Checks the rate against the laser's and the camera's.
Schedule make_gate_schedule(double repetition_rate_hz, double gate_width_s, const TimingLimits& limits);

}  // namespace plenopiv::drivers
