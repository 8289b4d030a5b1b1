// The sequencer: edge times for both cavities and the camera, and every refused constraint.
#include <gtest/gtest.h>

#include "core/base/errors.hpp"
#include "drivers/trigger/sequencer.hpp"

namespace plenopiv::drivers {
namespace {

std::string refusal(const TimingRequest& r, const TimingLimits& l = {}, double jitter = 0) {
  try {
    make_schedule(r, l, jitter, "user-space GPIO");
  } catch (const InputError& e) {
    return e.what();
  }
  return "";
}

double edge_time(const Schedule& s, TriggerLine line, bool rising) {
  for (const Edge& e : s.edges)
    if (e.line == line && e.rising == rising) return e.time_s;
  ADD_FAILURE() << "no edge on " << to_string(line);
  return -1;
}

TEST(Sequencer, PlacesBothCavitiesAndTheCamera) {
  TimingRequest r;
  r.repetition_rate_hz = 10;
  r.pulse_separation_s = 100e-6;
  r.flashlamp_to_qswitch_s = 180e-6;
  r.camera_pretrigger_s = 10e-6;
  r.exposure_a_s = 20e-6;
  TimingLimits l;
  l.interline_transfer_s = 5e-6;
  const Schedule s = make_schedule(r, l, 0);
  ASSERT_EQ(s.edges.size(), 10u);
  EXPECT_DOUBLE_EQ(s.edges.front().time_s, 0.0);  // flashlamp 1 is first
  EXPECT_EQ(s.edges.front().line, TriggerLine::Flashlamp1);
  const double q1 = edge_time(s, TriggerLine::QSwitch1, true);
  const double q2 = edge_time(s, TriggerLine::QSwitch2, true);
  EXPECT_NEAR(q1 - edge_time(s, TriggerLine::Flashlamp1, true), 180e-6, 1e-12);
  EXPECT_NEAR(q2 - edge_time(s, TriggerLine::Flashlamp2, true), 180e-6, 1e-12);
  EXPECT_NEAR(q2 - q1, 100e-6, 1e-12);
  EXPECT_NEAR(s.dt_s(), 100e-6, 1e-12);
  EXPECT_NEAR(q1 - edge_time(s, TriggerLine::Camera, true), 10e-6, 1e-12);
  EXPECT_NEAR(edge_time(s, TriggerLine::QSwitch1, false) - q1, 10e-6, 1e-12);
  EXPECT_NEAR(s.frame_b_start_s - s.pulse1_s, 15e-6, 1e-12);  // 20 - 10 + 5
  EXPECT_DOUBLE_EQ(s.period_s, 0.1);
  EXPECT_NEAR(s.smallest_margin_s, 10e-6, 1e-12);  // pulse 1 is 10 us before frame A ends
  EXPECT_EQ(s.smallest_margin_what, "pulse 1 before the end of frame A");
  for (std::size_t i = 1; i < s.edges.size(); ++i) EXPECT_LE(s.edges[i - 1].time_s, s.edges[i].time_s);
}

TEST(Sequencer, RefusesDtShorterThanTheTransferTime) {
  TimingRequest r;
  r.pulse_separation_s = 2e-6;
  TimingLimits l;
  l.interline_transfer_s = 5e-6;
  const std::string m = refusal(r, l);
  EXPECT_NE(m.find("pulse separation dt = 2 us is shorter than the camera's interline transfer "
                   "time 5 us"),
            std::string::npos)
      << m;
}

TEST(Sequencer, RefusesPulse2OutsideFrameB) {
  TimingRequest r;
  r.pulse_separation_s = 10e-6;  // frame B starts 15 us after pulse 1
  EXPECT_NE(refusal(r).find("pulse 2 falls before frame B starts (5 us early)"), std::string::npos) << refusal(r);
  r.pulse_separation_s = 0.06;  // frame B lasts 50 ms
  EXPECT_NE(refusal(r).find("pulse 2 falls after frame B ends"), std::string::npos) << refusal(r);
}

TEST(Sequencer, RefusesPulse1OutsideFrameAAndRatesAboveTheLasers) {
  TimingRequest r;
  r.camera_pretrigger_s = 30e-6;  // exposure 20 us: frame A ends before pulse 1
  EXPECT_NE(refusal(r).find("pulse 1 falls after frame A ends"), std::string::npos) << refusal(r);
  r = {};
  r.repetition_rate_hz = 20;
  EXPECT_NE(refusal(r).find("repetition rate 20 Hz is above the laser's maximum 15 Hz"), std::string::npos)
      << refusal(r);
  TimingLimits l;
  l.laser_max_rate_hz = 100;
  l.camera_max_pair_rate_hz = 5;
  r.repetition_rate_hz = 10;
  EXPECT_NE(refusal(r, l).find("above the camera's maximum 5 Hz"), std::string::npos);
  l.camera_max_pair_rate_hz = 100;
  r.repetition_rate_hz = 30;  // 33 ms period < frame B 50 ms
  EXPECT_NE(refusal(r, l).find("does not fit one period"), std::string::npos) << refusal(r, l);
}

TEST(Sequencer, RefusesAQSwitchDelayOutsideTheLasersWindowAndBadValues) {
  TimingRequest r;
  r.flashlamp_to_qswitch_s = 400e-6;
  EXPECT_NE(refusal(r).find("flashlamp-to-Q-switch delay 400 us is outside the laser's window"), std::string::npos)
      << refusal(r);
  r = {};
  r.pulse_separation_s = -1;
  EXPECT_NE(refusal(r).find("pulse_separation_s (dt) must be > 0"), std::string::npos);
  r = {};
  r.repetition_rate_hz = 0;
  EXPECT_NE(refusal(r).find("repetition_rate_hz must be > 0"), std::string::npos);
  r = {};
  r.flashlamp_pulse_width_s = 200e-6;
  EXPECT_NE(refusal(r).find("flashlamp_pulse_width_s"), std::string::npos);
}

TEST(Sequencer, RefusesMarginsBelowTheBackendsJitterAndPointsToHardwareTiming) {
  TimingRequest r;  // smallest margin 10 us
  const std::string m = refusal(r, {}, 50e-6);
  EXPECT_NE(m.find("user-space GPIO places edges to within +-50 us"), std::string::npos) << m;
  EXPECT_NE(m.find("pulse 1 before the end of frame A: 10 us"), std::string::npos) << m;
  EXPECT_NE(m.find("hardware-timed mode"), std::string::npos) << m;
  // A slow schedule with generous margins is fine even for user-space GPIO.
  r.pulse_separation_s = 2e-3;
  r.camera_pretrigger_s = 1e-3;
  r.exposure_a_s = 1.5e-3;
  r.flashlamp_to_qswitch_s = 175e-6;
  EXPECT_EQ(refusal(r, {}, 50e-6), "");
  // Hardware-timed mode: one gate pulse per shot.
  const Schedule g = make_gate_schedule(10, 100e-6, {});
  ASSERT_EQ(g.edges.size(), 2u);
  EXPECT_EQ(g.edges[0].line, TriggerLine::Gate);
  EXPECT_THROW(make_gate_schedule(50, 100e-6, {}), InputError);
}

}  // namespace
}  // namespace plenopiv::drivers
