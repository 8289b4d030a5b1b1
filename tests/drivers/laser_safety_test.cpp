// Laser safety: schedules are checked in the integer nanoseconds they are played in, and no laser
// line ever rises sooner than the laser allows, over random schedules and random playback delays.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <map>
#include <random>
#include <thread>

#include "core/base/errors.hpp"
#include "drivers/trigger/sequencer.hpp"
#include "drivers/trigger/sim_trigger.hpp"
#include "drivers/trigger/trigger_registry.hpp"

namespace plenopiv::drivers {
namespace {

using namespace std::chrono_literals;

std::string refusal(const TimingRequest& r, const TimingLimits& l = {}) {
  try {
    make_schedule(r, l, 0);
  } catch (const InputError& e) {
    return e.what();
  }
  return "";
}

std::string check_refusal(const Schedule& s) {
  try {
    check_schedule(s);
  } catch (const InputError& e) {
    return e.what();
  }
  return "";
}

TEST(LaserSafety, RatesThatOverflowNanosecondsOrAreNotNumbersAreRefused) {
  TimingRequest r;
  // The reproducer: 1e-12 Hz passed the 15 Hz checks in floating point and overflowed the
  // playback's nanosecond clock, firing shots 0.05-0.13 s apart.
  r.repetition_rate_hz = 1e-12;
  EXPECT_NE(refusal(r).find("below one pair per 3600 s"), std::string::npos) << refusal(r);
  for (double bad : {std::nan(""), std::numeric_limits<double>::infinity(), -1.0, 0.0}) {
    r.repetition_rate_hz = bad;
    EXPECT_NE(refusal(r).find("repetition_rate_hz"), std::string::npos) << bad << ": " << refusal(r);
    EXPECT_THROW(make_gate_schedule(bad, 10e-6, {}), InputError) << bad;
  }
  EXPECT_THROW(make_gate_schedule(1e-12, 10e-6, {}), InputError);
  // Every other time of the request and every limit is a number too.
  const double nan = std::nan("");
  for (double TimingRequest::*field :
       {&TimingRequest::pulse_separation_s, &TimingRequest::flashlamp_to_qswitch_s, &TimingRequest::camera_pretrigger_s,
        &TimingRequest::exposure_a_s, &TimingRequest::flashlamp_pulse_width_s, &TimingRequest::qswitch_pulse_width_s,
        &TimingRequest::camera_pulse_width_s}) {
    TimingRequest bad;
    bad.*field = nan;
    EXPECT_NE(refusal(bad), "") << "a NaN request time was accepted";
  }
  for (double TimingLimits::*field : {&TimingLimits::laser_max_rate_hz, &TimingLimits::min_flashlamp_to_qswitch_s,
                                      &TimingLimits::max_flashlamp_to_qswitch_s, &TimingLimits::interline_transfer_s,
                                      &TimingLimits::frame_b_s, &TimingLimits::camera_max_pair_rate_hz}) {
    TimingLimits bad;
    bad.*field = nan;
    EXPECT_NE(refusal({}, bad), "") << "a NaN limit was accepted";
  }
  TimingLimits slow_laser;
  slow_laser.laser_max_rate_hz = 1e-12;
  EXPECT_NE(refusal({}, slow_laser).find("laser_max_rate_hz"), std::string::npos) << refusal({}, slow_laser);
}

TEST(LaserSafety, TheScheduleIsCheckedInIntegerNanoseconds) {
  TimingRequest r;
  r.repetition_rate_hz = 15;  // exactly the laser's maximum: allowed
  const Schedule s = make_schedule(r, {}, 0);
  EXPECT_EQ(s.period_ns, 66'666'667);
  EXPECT_EQ(s.min_laser_interval_ns, 66'666'667);
  for (const Edge& e : s.edges) EXPECT_DOUBLE_EQ(e.time_s, double(e.time_ns) * 1e-9);
  EXPECT_EQ(check_refusal(s), "");

  // Hand-built schedules are held to the same rules, by check_schedule and by every trigger's load.
  auto refused = [&](Schedule bad, const std::string& why) {
    const std::string m = check_refusal(bad);
    EXPECT_NE(m.find(why), std::string::npos) << m;
    auto t = open_trigger("sim://?clock=virtual");
    EXPECT_THROW(t->load(bad), InputError) << why;
  };
  Schedule bad = s;
  bad.period_ns -= 1;  // one nanosecond faster than the laser allows
  refused(bad, "shorter than the laser allows");
  bad = s;
  bad.period_ns = 0;
  refused(bad, "outside (0,");
  bad = s;
  bad.period_ns = kMaxPeriodNs + 1;
  refused(bad, "outside (0,");
  bad = s;
  bad.min_laser_interval_ns = 0;
  refused(bad, "minimum interval");
  bad = s;
  bad.edges.back().time_ns = s.period_ns;
  refused(bad, "outside the period");
  bad = s;
  bad.edges[0].time_ns = 5;  // flashlamp 1 rises after the edge that follows it
  bad.edges[1].time_ns = 0;
  refused(bad, "not in time order");
  bad = s;
  bad.edges.pop_back();  // the last falling edge: a line left high
  refused(bad, "still high at the end of the period");
  bad = s;
  // Flashlamp 1 twice in one period: a second shot of cavity 1 inside the period.
  bad.edges.push_back({s.period_ns - 2, 0, TriggerLine::Flashlamp1, true});
  bad.edges.push_back({s.period_ns - 1, 0, TriggerLine::Flashlamp1, false});
  refused(bad, "flashlamp1 fires 2 times per period");
  bad = s;
  bad.edges.clear();
  refused(bad, "no edges");
}

// Rising edges of each laser line, in the order written, with the times they were written.
std::map<TriggerLine, std::vector<double>> laser_rises(const std::vector<RecordedEdge>& edges) {
  std::map<TriggerLine, std::vector<double>> rises;
  for (const RecordedEdge& e : edges) {
    if (e.level && is_laser_line(e.line)) rises[e.line].push_back(e.actual_s);
  }
  return rises;
}

TEST(LaserSafety, NoCavityFiresFasterThanItsLimitWhateverThePlaybackDelays) {
  std::mt19937_64 random(20261125);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  int delayed_somewhere = 0;
  for (int trial = 0; trial < 300; ++trial) {
    // A random schedule the sequencer accepts: rate up to the laser's maximum, dt and delays in range.
    TimingLimits limits;
    limits.laser_max_rate_hz = 5 + 25 * unit(random);
    limits.camera_max_pair_rate_hz = limits.laser_max_rate_hz;
    limits.frame_b_s = 0.01;
    TimingRequest r;
    r.repetition_rate_hz = limits.laser_max_rate_hz * (0.3 + 0.7 * unit(random));
    if (trial % 5 == 0) r.repetition_rate_hz = limits.laser_max_rate_hz;  // at the limit exactly
    r.pulse_separation_s = 20e-6 + 2e-3 * unit(random);
    r.flashlamp_to_qswitch_s = 120e-6 + 120e-6 * unit(random);
    r.exposure_a_s = 30e-6;
    Schedule schedule;
    try {
      schedule = make_schedule(r, limits, 0);
    } catch (const InputError&) {
      continue;  // e.g. dt beyond frame B: not a schedule a trigger could get
    }
    // Random lateness: none, uniform jitter up to a period, or rare long stalls.
    const std::int64_t period = schedule.period_ns;
    const int model = trial % 3;
    std::vector<std::int64_t> delays(40 * schedule.edges.size());
    for (auto& d : delays) {
      const double u = unit(random);
      d = model == 0   ? 0
          : model == 1 ? std::int64_t(u * double(period))
                       : (u < 0.05 ? std::int64_t(3 * double(period) * unit(random)) : 0);
    }
    auto t = open_trigger("sim://?clock=virtual");
    auto* sim = dynamic_cast<SimTrigger*>(t.get());
    ASSERT_NE(sim, nullptr);
    const std::size_t per_shot = schedule.edges.size();
    sim->set_virtual_delays(
        [&](std::uint64_t shot, std::size_t edge) { return delays[(shot * per_shot + edge) % delays.size()]; });
    t->load(schedule);
    const std::uint64_t shots = 40;
    t->start(shots);
    for (int i = 0; i < 2000 && t->running(); ++i) std::this_thread::sleep_for(1ms);
    ASSERT_FALSE(t->running());

    const double min_interval_s = double(schedule.min_laser_interval_ns) * 1e-9;
    for (const auto& [line, times] : laser_rises(sim->edges())) {
      for (std::size_t i = 1; i < times.size(); ++i) {
        ASSERT_GE(times[i] - times[i - 1], min_interval_s - 1e-12)
            << "trial " << trial << ": " << to_string(line) << " rose " << (times[i] - times[i - 1]) * 1e3
            << " ms after its previous rising edge; the laser allows " << min_interval_s * 1e3 << " ms";
      }
    }
    // Every line ends low, and on every line the recorded edges alternate, starting rising.
    std::map<TriggerLine, bool> level;
    for (const RecordedEdge& e : sim->edges()) {
      ASSERT_NE(level[e.line], e.level) << "trial " << trial << ": " << to_string(e.line) << " written twice";
      level[e.line] = e.level;
    }
    for (TriggerLine l : kTriggerLines) {
      EXPECT_FALSE(sim->level(l)) << to_string(l);
      EXPECT_FALSE(level[l]) << "trial " << trial << ": " << to_string(l) << " ends high";
    }
    // Every shot fires, whole: one that came too soon after a late one was moved, not dropped.
    const TriggerCounters c = t->counters();
    EXPECT_EQ(c.shots_fired, shots) << "trial " << trial;
    EXPECT_EQ(c.shots_abandoned, 0u) << "trial " << trial;
    if (model == 0) {
      EXPECT_EQ(c.shots_delayed, 0u) << "on-time playback moves nothing";
    }
    delayed_somewhere += c.shots_delayed > 0;
  }
  // The delays did push shots together: the guard was exercised, not just never needed.
  EXPECT_GT(delayed_somewhere, 10);
}

TEST(LaserSafety, ARunStartedRightAfterAnotherWaitsOutTheLasersInterval) {
  TimingRequest r;
  r.repetition_rate_hz = 14;  // the period (71.4 ms) is just above the laser's 66.7 ms
  r.pulse_separation_s = 1e-3;
  r.camera_pretrigger_s = 100e-6;
  r.exposure_a_s = 200e-6;
  const Schedule s = make_schedule(r, {}, 0);
  // Two playbacks of one shot each on the same line, back to back: the second waits.
  auto first = open_trigger("sim://?clock=real");
  first->load(s);
  first->start(1);
  for (int i = 0; i < 1000 && first->running(); ++i) std::this_thread::sleep_for(1ms);
  const auto first_done = std::chrono::steady_clock::now();
  first.reset();
  auto second = open_trigger("sim://?clock=real");
  auto* sim = dynamic_cast<SimTrigger*>(second.get());
  second->load(s);
  second->start(1);
  for (int i = 0; i < 1000 && second->running(); ++i) std::this_thread::sleep_for(1ms);
  EXPECT_EQ(second->counters().shots_fired, 1u);
  EXPECT_EQ(second->counters().shots_abandoned, 0u);
  // Its first laser edge (flashlamp 1, at the start of its period) came at least the laser's
  // interval after the first run's, which came ~80 us of its own period before it ended.
  double flashlamp = -1;
  for (const RecordedEdge& e : sim->edges()) {
    if (e.line == TriggerLine::Flashlamp1 && e.level) flashlamp = e.actual_s;
  }
  ASSERT_GE(flashlamp, 0);
  const double waited = std::chrono::duration<double>(std::chrono::steady_clock::now() - first_done).count();
  EXPECT_GT(waited, double(s.min_laser_interval_ns) * 1e-9 - 0.005)
      << "the second playback finished only " << waited * 1e3 << " ms after the first";
}

}  // namespace
}  // namespace plenopiv::drivers
