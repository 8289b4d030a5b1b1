// Turns PIV timing (rate, dt, flashlamp-to-Q-switch delay, camera timing) into a schedule of line
// edges for both laser cavities and the camera, refusing schedules that break a constraint. Pure.
#include "drivers/trigger/sequencer.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>

#include "core/base/errors.hpp"

namespace plenopiv::drivers {
namespace {

std::string us(double s) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.3g us", s * 1e6);
  return buf;
}

std::string hz_text(double f) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.4g Hz", f);
  return buf;
}

[[noreturn]] void refuse(const std::string& message) { throw InputError("trigger schedule refused: " + message); }

void require_positive(double v, const char* name) {
  if (!(v > 0) || !std::isfinite(v)) refuse(std::string(name) + " must be > 0, got " + us(v));
}

// A repetition rate: finite, and at least one pair per kMaxPeriodNs.
void require_rate(double hz, const char* name) {
  if (!(hz > 0) || !std::isfinite(hz)) refuse(std::string(name) + " must be > 0, got " + hz_text(hz));
  if (hz < 1e9 / double(kMaxPeriodNs)) {
    refuse(std::string(name) + " " + hz_text(hz) + " is below one pair per " +
           std::to_string(kMaxPeriodNs / 1'000'000'000) + " s");
  }
}

// The laser's and camera's limits: finite, rates as require_rate, times >= 0.
void check_limits(const TimingLimits& l) {
  require_rate(l.laser_max_rate_hz, "laser_max_rate_hz");
  require_rate(l.camera_max_pair_rate_hz, "camera_max_pair_rate_hz");
  for (const auto& [v, name] :
       {std::pair{l.min_flashlamp_to_qswitch_s, "min_flashlamp_to_qswitch_s"},
        std::pair{l.max_flashlamp_to_qswitch_s, "max_flashlamp_to_qswitch_s"},
        std::pair{l.interline_transfer_s, "interline_transfer_s"}, std::pair{l.frame_b_s, "frame_b_s"}}) {
    if (!(v >= 0) || !std::isfinite(v)) refuse(std::string(name) + " must be >= 0, got " + us(v));
  }
}

// Seconds to whole nanoseconds; `s` is finite and within one period (<= kMaxPeriodNs).
std::int64_t to_ns(double s) { return std::llround(s * 1e9); }

// The laser's minimum time between two rising edges of one laser line, rounded up to whole ns.
std::int64_t min_interval_ns(double max_rate_hz) { return std::int64_t(std::ceil(1e9 / max_rate_hz - 1e-6)); }

std::string ns_text(std::int64_t ns) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "%lld ns", static_cast<long long>(ns));
  return buf;
}

// Fills the integer times from the edges' seconds (already checked to lie within one period).
void set_integer_times(Schedule& s, double rate_hz, const TimingLimits& limits) {
  s.period_ns = to_ns(1.0 / rate_hz);
  s.period_s = double(s.period_ns) * 1e-9;
  s.min_laser_interval_ns = min_interval_ns(limits.laser_max_rate_hz);
  for (Edge& e : s.edges) {
    e.time_ns = to_ns(e.time_s);
    e.time_s = double(e.time_ns) * 1e-9;
  }
  std::stable_sort(s.edges.begin(), s.edges.end(), [](const Edge& a, const Edge& b) { return a.time_ns < b.time_ns; });
  check_schedule(s);
}

}  // namespace

bool is_laser_line(TriggerLine line) { return line != TriggerLine::Camera; }

void check_schedule(const Schedule& s) {
  if (s.period_ns <= 0 || s.period_ns > kMaxPeriodNs) {
    refuse("period " + ns_text(s.period_ns) + " is outside (0, " + ns_text(kMaxPeriodNs) + "]");
  }
  if (s.min_laser_interval_ns <= 0 || s.min_laser_interval_ns > kMaxPeriodNs) {
    refuse("the laser's minimum interval " + ns_text(s.min_laser_interval_ns) + " is outside (0, " +
           ns_text(kMaxPeriodNs) + "]");
  }
  if (s.period_ns < s.min_laser_interval_ns) {
    refuse("period " + ns_text(s.period_ns) + " is shorter than the laser allows between two shots (" +
           ns_text(s.min_laser_interval_ns) + "): lower the repetition rate");
  }
  if (s.edges.empty()) refuse("the schedule has no edges");
  std::array<bool, kTriggerLines.size()> high{};
  std::array<int, kTriggerLines.size()> rises{};
  std::int64_t previous = 0;
  for (const Edge& e : s.edges) {
    const int line = int(e.line);
    if (line < 0 || line >= int(kTriggerLines.size())) refuse("an edge names no trigger line");
    const std::string name = to_string(e.line);
    if (e.time_ns < 0 || e.time_ns >= s.period_ns) {
      refuse(name + " edge at " + ns_text(e.time_ns) + " lies outside the period of " + ns_text(s.period_ns));
    }
    if (e.time_ns < previous) refuse("edges are not in time order (" + name + " at " + ns_text(e.time_ns) + ")");
    previous = e.time_ns;
    if (e.rising == high[line]) {
      refuse(name + (e.rising ? " rises while already high" : " falls while already low") + " at " +
             ns_text(e.time_ns));
    }
    high[line] = e.rising;
    if (e.rising) ++rises[line];
  }
  for (TriggerLine l : kTriggerLines) {
    if (high[int(l)]) refuse(std::string(to_string(l)) + " is still high at the end of the period");
    if (is_laser_line(l) && rises[int(l)] > 1) {
      refuse(std::string(to_string(l)) + " fires " + std::to_string(rises[int(l)]) +
             " times per period; a laser line fires at most once");
    }
  }
}

const char* to_string(TriggerLine line) {
  switch (line) {
    case TriggerLine::Flashlamp1:
      return "flashlamp1";
    case TriggerLine::QSwitch1:
      return "qswitch1";
    case TriggerLine::Flashlamp2:
      return "flashlamp2";
    case TriggerLine::QSwitch2:
      return "qswitch2";
    case TriggerLine::Camera:
      return "camera";
    case TriggerLine::Gate:
      return "gate";
  }
  return "?";
}

Schedule make_schedule(const TimingRequest& r, const TimingLimits& limits, double timing_uncertainty_s,
                       const std::string& backend) {
  check_limits(limits);
  require_rate(r.repetition_rate_hz, "repetition_rate_hz");
  require_positive(r.pulse_separation_s, "pulse_separation_s (dt)");
  require_positive(r.flashlamp_to_qswitch_s, "flashlamp_to_qswitch_s");
  require_positive(r.exposure_a_s, "exposure_a_s");
  require_positive(r.flashlamp_pulse_width_s, "flashlamp_pulse_width_s");
  require_positive(r.qswitch_pulse_width_s, "qswitch_pulse_width_s");
  require_positive(r.camera_pulse_width_s, "camera_pulse_width_s");
  if (!(r.camera_pretrigger_s >= 0) || !std::isfinite(r.camera_pretrigger_s))
    refuse("camera_pretrigger_s must be >= 0, got " + us(r.camera_pretrigger_s));

  // Rates: each cavity fires once per period.
  if (r.repetition_rate_hz > limits.laser_max_rate_hz) {
    refuse("repetition rate " + hz_text(r.repetition_rate_hz) + " is above the laser's maximum " +
           hz_text(limits.laser_max_rate_hz));
  }
  if (r.repetition_rate_hz > limits.camera_max_pair_rate_hz) {
    refuse("repetition rate " + hz_text(r.repetition_rate_hz) + " is above the camera's maximum " +
           hz_text(limits.camera_max_pair_rate_hz) + " frame pairs per second");
  }
  if (r.flashlamp_to_qswitch_s < limits.min_flashlamp_to_qswitch_s ||
      r.flashlamp_to_qswitch_s > limits.max_flashlamp_to_qswitch_s) {
    refuse("flashlamp-to-Q-switch delay " + us(r.flashlamp_to_qswitch_s) + " is outside the laser's window " +
           us(limits.min_flashlamp_to_qswitch_s) + " .. " + us(limits.max_flashlamp_to_qswitch_s) +
           " (typically 150-200 us)");
  }
  // The camera: frame A from its trigger for exposure_a, then the interline transfer, then frame B.
  if (r.pulse_separation_s < limits.interline_transfer_s) {
    refuse("pulse separation dt = " + us(r.pulse_separation_s) +
           " is shorter than the camera's interline transfer time " + us(limits.interline_transfer_s) +
           ": pulse 2 would come before frame B starts");
  }

  // Time axis with pulse 1 at 0 first; shifted so that the earliest edge is at 0 afterwards.
  const double p1 = 0.0;
  const double p2 = r.pulse_separation_s;
  const double cam = p1 - r.camera_pretrigger_s;
  const double a_end = cam + r.exposure_a_s;
  const double b_start = a_end + limits.interline_transfer_s;
  const double b_end = b_start + limits.frame_b_s;

  struct Margin {
    double slack;
    std::string what;
  };
  std::vector<Margin> margins{
      {a_end - p1, "pulse 1 before the end of frame A"},
      {p2 - b_start, "pulse 2 after the start of frame B"},
      {b_end - p2, "pulse 2 before the end of frame B"},
      {r.flashlamp_to_qswitch_s - limits.min_flashlamp_to_qswitch_s,
       "flashlamp-to-Q-switch delay above the laser's minimum"},
      {limits.max_flashlamp_to_qswitch_s - r.flashlamp_to_qswitch_s,
       "flashlamp-to-Q-switch delay below the laser's maximum"},
  };
  if (a_end - p1 < 0) {
    refuse("pulse 1 falls after frame A ends (" + us(p1 - a_end) + " late): raise exposure_a_s or camera_pretrigger_s");
  }
  if (cam > p1) refuse("the camera trigger comes after pulse 1");
  if (p2 < b_start) {
    refuse("pulse 2 falls before frame B starts (" + us(b_start - p2) + " early): frame A ends " + us(a_end - p1) +
           " after pulse 1 and the transfer takes " + us(limits.interline_transfer_s) +
           "; raise dt or shorten exposure_a_s / the pretrigger");
  }
  if (p2 > b_end) {
    refuse("pulse 2 falls after frame B ends (" + us(p2 - b_end) + " late): shorten dt");
  }

  Schedule s;
  std::vector<Edge> edges;
  auto pulse = [&](TriggerLine line, double t, double width) {
    edges.push_back({0, t, line, true});
    edges.push_back({0, t + width, line, false});
  };
  pulse(TriggerLine::Flashlamp1, p1 - r.flashlamp_to_qswitch_s, r.flashlamp_pulse_width_s);
  pulse(TriggerLine::QSwitch1, p1, r.qswitch_pulse_width_s);
  pulse(TriggerLine::Flashlamp2, p2 - r.flashlamp_to_qswitch_s, r.flashlamp_pulse_width_s);
  pulse(TriggerLine::QSwitch2, p2, r.qswitch_pulse_width_s);
  pulse(TriggerLine::Camera, cam, r.camera_pulse_width_s);

  // A line's pulse must end before the Q-switch of the same cavity (flashlamp) and fit the period.
  if (r.flashlamp_pulse_width_s >= r.flashlamp_to_qswitch_s) {
    refuse("flashlamp_pulse_width_s " + us(r.flashlamp_pulse_width_s) +
           " must be shorter than the flashlamp-to-Q-switch delay " + us(r.flashlamp_to_qswitch_s));
  }
  const auto [lo, hi] =
      std::minmax_element(edges.begin(), edges.end(), [](const Edge& a, const Edge& b) { return a.time_s < b.time_s; });
  const double t0 = lo->time_s;
  const double span = hi->time_s - t0;
  const double period = 1.0 / r.repetition_rate_hz;
  const double busy = std::max(span, b_end - t0);  // edges, and frame B still collecting light
  margins.push_back({period - busy, "one period holds the whole sequence and frame B"});
  if (margins.back().slack < 0) {
    refuse("the sequence (edges and frame B: " + us(busy) + ") does not fit one period of " + us(period) +
           ": lower the repetition rate");
  }
  for (Edge& e : edges) e.time_s -= t0;
  s.edges = std::move(edges);
  set_integer_times(s, r.repetition_rate_hz, limits);
  s.pulse1_s = p1 - t0;
  s.pulse2_s = p2 - t0;
  s.frame_a_end_s = a_end - t0;
  s.frame_b_start_s = b_start - t0;
  s.frame_b_end_s = b_end - t0;

  const auto tight = std::min_element(margins.begin(), margins.end(),
                                      [](const Margin& a, const Margin& b) { return a.slack < b.slack; });
  s.smallest_margin_s = tight->slack;
  s.smallest_margin_what = tight->what;
  if (timing_uncertainty_s > 0 && s.smallest_margin_s < timing_uncertainty_s) {
    refuse(backend + " places edges to within +-" + us(timing_uncertainty_s) +
           ", more than this schedule's smallest margin (" + s.smallest_margin_what + ": " + us(s.smallest_margin_s) +
           "). Use hardware-timed mode: an external delay generator "
           "makes the laser and camera pulses, and plenopiv only arms it and gates the shot train");
  }
  return s;
}

}  // namespace plenopiv::drivers

namespace plenopiv::drivers {

Schedule make_gate_schedule(double repetition_rate_hz, double gate_width_s, const TimingLimits& limits) {
  check_limits(limits);
  require_rate(repetition_rate_hz, "repetition_rate_hz");
  require_positive(gate_width_s, "gate_width_s");
  if (repetition_rate_hz > limits.laser_max_rate_hz) {
    refuse("repetition rate " + hz_text(repetition_rate_hz) + " is above the laser's maximum " +
           hz_text(limits.laser_max_rate_hz));
  }
  if (repetition_rate_hz > limits.camera_max_pair_rate_hz) {
    refuse("repetition rate " + hz_text(repetition_rate_hz) + " is above the camera's maximum " +
           hz_text(limits.camera_max_pair_rate_hz) + " frame pairs per second");
  }
  const double period = 1.0 / repetition_rate_hz;
  if (gate_width_s >= period / 2) refuse("gate_width_s " + us(gate_width_s) + " must be under half a period");
  Schedule s;
  s.edges = {{0, 0.0, TriggerLine::Gate, true}, {0, gate_width_s, TriggerLine::Gate, false}};
  set_integer_times(s, repetition_rate_hz, limits);
  s.smallest_margin_s = period - gate_width_s;
  s.smallest_margin_what = "hardware-timed: the delay generator owns the pulse timing";
  return s;
}

}  // namespace plenopiv::drivers
