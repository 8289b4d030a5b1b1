// Turns PIV timing (rate, dt, flashlamp-to-Q-switch delay, camera timing) into a schedule of line
// edges for both laser cavities and the camera, refusing schedules that break a constraint. Pure.
#include "drivers/trigger/sequencer.hpp"

#include <algorithm>
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

std::string hz(double f) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.4g Hz", f);
  return buf;
}

[[noreturn]] void refuse(const std::string& message) {
  throw InputError("trigger schedule refused: " + message);
}

void require_positive(double v, const char* name) {
  if (!(v > 0) || !std::isfinite(v)) refuse(std::string(name) + " must be > 0, got " + us(v));
}

}  // namespace

const char* to_string(TriggerLine line) {
  switch (line) {
    case TriggerLine::Flashlamp1: return "flashlamp1";
    case TriggerLine::QSwitch1: return "qswitch1";
    case TriggerLine::Flashlamp2: return "flashlamp2";
    case TriggerLine::QSwitch2: return "qswitch2";
    case TriggerLine::Camera: return "camera";
    case TriggerLine::Gate: return "gate";
  }
  return "?";
}

Schedule make_schedule(const TimingRequest& r, const TimingLimits& limits,
                       double timing_uncertainty_s, const std::string& backend) {
  if (!(r.repetition_rate_hz > 0) || !std::isfinite(r.repetition_rate_hz)) {
    refuse("repetition_rate_hz must be > 0, got " + hz(r.repetition_rate_hz));
  }
  require_positive(r.pulse_separation_s, "pulse_separation_s (dt)");
  require_positive(r.flashlamp_to_qswitch_s, "flashlamp_to_qswitch_s");
  require_positive(r.exposure_a_s, "exposure_a_s");
  require_positive(r.flashlamp_pulse_width_s, "flashlamp_pulse_width_s");
  require_positive(r.qswitch_pulse_width_s, "qswitch_pulse_width_s");
  require_positive(r.camera_pulse_width_s, "camera_pulse_width_s");
  if (r.camera_pretrigger_s < 0) refuse("camera_pretrigger_s must be >= 0, got " + us(r.camera_pretrigger_s));

  // Rates: each cavity fires once per period.
  if (r.repetition_rate_hz > limits.laser_max_rate_hz) {
    refuse("repetition rate " + hz(r.repetition_rate_hz) + " is above the laser's maximum " +
           hz(limits.laser_max_rate_hz));
  }
  if (r.repetition_rate_hz > limits.camera_max_pair_rate_hz) {
    refuse("repetition rate " + hz(r.repetition_rate_hz) + " is above the camera's maximum " +
           hz(limits.camera_max_pair_rate_hz) + " frame pairs per second");
  }
  if (r.flashlamp_to_qswitch_s < limits.min_flashlamp_to_qswitch_s ||
      r.flashlamp_to_qswitch_s > limits.max_flashlamp_to_qswitch_s) {
    refuse("flashlamp-to-Q-switch delay " + us(r.flashlamp_to_qswitch_s) +
           " is outside the laser's window " + us(limits.min_flashlamp_to_qswitch_s) + " .. " +
           us(limits.max_flashlamp_to_qswitch_s) + " (typically 150-200 us)");
  }
  // The camera: frame A from its trigger for exposure_a, then the interline transfer, then frame B.
  if (r.pulse_separation_s < limits.interline_transfer_s) {
    refuse("pulse separation dt = " + us(r.pulse_separation_s) +
           " is shorter than the camera's interline transfer time " +
           us(limits.interline_transfer_s) + ": pulse 2 would come before frame B starts");
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
    refuse("pulse 1 falls after frame A ends (" + us(p1 - a_end) +
           " late): raise exposure_a_s or camera_pretrigger_s");
  }
  if (cam > p1) refuse("the camera trigger comes after pulse 1");
  if (p2 < b_start) {
    refuse("pulse 2 falls before frame B starts (" + us(b_start - p2) +
           " early): frame A ends " + us(a_end - p1) + " after pulse 1 and the transfer takes " +
           us(limits.interline_transfer_s) + "; raise dt or shorten exposure_a_s / the pretrigger");
  }
  if (p2 > b_end) {
    refuse("pulse 2 falls after frame B ends (" + us(p2 - b_end) + " late): shorten dt");
  }

  Schedule s;
  std::vector<Edge> edges;
  auto pulse = [&](TriggerLine line, double t, double width) {
    edges.push_back({t, line, true});
    edges.push_back({t + width, line, false});
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
  const auto [lo, hi] = std::minmax_element(edges.begin(), edges.end(), [](const Edge& a, const Edge& b) {
    return a.time_s < b.time_s;
  });
  const double t0 = lo->time_s;
  const double span = hi->time_s - t0;
  const double period = 1.0 / r.repetition_rate_hz;
  const double busy = std::max(span, b_end - t0);  // edges, and frame B still collecting light
  margins.push_back({period - busy, "one period holds the whole sequence and frame B"});
  if (margins.back().slack < 0) {
    refuse("the sequence (edges and frame B: " + us(busy) + ") does not fit one period of " +
           us(period) + ": lower the repetition rate");
  }
  for (Edge& e : edges) e.time_s -= t0;
  std::stable_sort(edges.begin(), edges.end(),
                   [](const Edge& a, const Edge& b) { return a.time_s < b.time_s; });
  s.edges = std::move(edges);
  s.period_s = period;
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
           ", more than this schedule's smallest margin (" + s.smallest_margin_what + ": " +
           us(s.smallest_margin_s) + "). Use hardware-timed mode: an external delay generator "
           "makes the laser and camera pulses, and plenopiv only arms it and gates the shot train");
  }
  return s;
}

}  // namespace plenopiv::drivers

namespace plenopiv::drivers {

Schedule make_gate_schedule(double repetition_rate_hz, double gate_width_s, const TimingLimits& limits) {
  if (!(repetition_rate_hz > 0) || !std::isfinite(repetition_rate_hz)) {
    refuse("repetition_rate_hz must be > 0, got " + hz(repetition_rate_hz));
  }
  require_positive(gate_width_s, "gate_width_s");
  if (repetition_rate_hz > limits.laser_max_rate_hz) {
    refuse("repetition rate " + hz(repetition_rate_hz) + " is above the laser's maximum " +
           hz(limits.laser_max_rate_hz));
  }
  if (repetition_rate_hz > limits.camera_max_pair_rate_hz) {
    refuse("repetition rate " + hz(repetition_rate_hz) + " is above the camera's maximum " +
           hz(limits.camera_max_pair_rate_hz) + " frame pairs per second");
  }
  const double period = 1.0 / repetition_rate_hz;
  if (gate_width_s >= period / 2) refuse("gate_width_s " + us(gate_width_s) + " must be under half a period");
  Schedule s;
  s.edges = {{0.0, TriggerLine::Gate, true}, {gate_width_s, TriggerLine::Gate, false}};
  s.period_s = period;
  s.smallest_margin_s = period - gate_width_s;
  s.smallest_margin_what = "hardware-timed: the delay generator owns the pulse timing";
  return s;
}

}  // namespace plenopiv::drivers
