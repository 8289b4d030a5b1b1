// Triggers: the sim backend records every edge, measures dt, leaves lines low; gpiod URI and
// line mapping without a chip; a real chip only when /dev/gpiochip* exists.
#include <gtest/gtest.h>

#include <filesystem>

#include "core/base/errors.hpp"
#include "drivers/common/driver_errors.hpp"
#include "drivers/trigger/gpiod/line_map.hpp"
#include "drivers/trigger/sim_trigger.hpp"
#include "drivers/trigger/trigger_registry.hpp"

namespace plenopiv::drivers {
namespace {

using namespace std::chrono_literals;

std::string open_error(const std::string& uri) {
  try {
    open_trigger(uri);
  } catch (const InputError& e) {
    return e.what();
  }
  return "";
}

Schedule fast_schedule(double rate_hz = 10) {
  TimingRequest r;
  r.repetition_rate_hz = rate_hz;
  r.pulse_separation_s = 2e-3;
  r.camera_pretrigger_s = 1e-3;
  r.exposure_a_s = 1.5e-3;
  TimingLimits l;
  l.laser_max_rate_hz = 100;
  l.camera_max_pair_rate_hz = 100;
  l.frame_b_s = 5e-3;
  return make_schedule(r, l, 0);
}

TEST(TriggerRegistry, UnknownSchemesAndBadUrisAreClearErrors) {
  EXPECT_NE(open_error("ttl://x").find("unknown trigger scheme 'ttl' (known: gpiod, sim)"), std::string::npos)
      << open_error("ttl://x");
  EXPECT_NE(open_error("sim://?clock=fast").find("clock must be real or virtual"), std::string::npos);
  EXPECT_NE(open_error("sim://?jitter=1").find("unknown parameter 'jitter'"), std::string::npos);
}

TEST(SimTrigger, RecordsEveryEdgeOfEveryShotInVirtualTime) {
  auto t = open_trigger("sim://?clock=virtual");
  auto* sim = dynamic_cast<SimTrigger*>(t.get());
  ASSERT_NE(sim, nullptr);
  const Schedule s = fast_schedule();
  t->load(s);
  std::vector<RecordedEdge> heard;
  sim->set_edge_listener([&](const RecordedEdge& e) {
    if (e.line == TriggerLine::Camera && e.level) heard.push_back(e);
  });
  t->start(3);
  for (int i = 0; i < 100 && t->running(); ++i) std::this_thread::sleep_for(1ms);
  EXPECT_FALSE(t->running());
  const auto edges = sim->edges();
  ASSERT_EQ(edges.size(), 3 * s.edges.size());
  for (std::size_t i = 0; i < edges.size(); ++i) {
    const Edge& planned = s.edges[i % s.edges.size()];
    EXPECT_EQ(edges[i].line, planned.line);
    EXPECT_EQ(edges[i].level, planned.rising);
    EXPECT_NEAR(edges[i].planned_s, double(i / s.edges.size()) * s.period_s + planned.time_s, 1e-12);
  }
  EXPECT_EQ(heard.size(), 3u);  // the simulated camera's seam
  for (TriggerLine l : kTriggerLines) EXPECT_FALSE(sim->level(l)) << to_string(l);
  // The Q-switch sync gives one measured shot per double pulse with the dt that happened.
  for (int i = 0; i < 3; ++i) {
    auto shot = t->next_shot(100ms);
    ASSERT_TRUE(shot);
    EXPECT_EQ(shot->shot_index, std::uint64_t(i));
    EXPECT_NEAR(shot->dt_s(), 2e-3, 1e-9);
  }
  EXPECT_EQ(t->counters().shots_fired, 3u);
  EXPECT_EQ(t->counters().sync_unpaired, 0u);
}

TEST(SimTrigger, RealTimePlaybackStopsWithAllLinesLow) {
  auto t = open_trigger("sim://");
  auto* sim = dynamic_cast<SimTrigger*>(t.get());
  t->load(fast_schedule(50));
  t->start(0);
  EXPECT_THROW(t->load(fast_schedule()), StateError);
  EXPECT_THROW(t->start(1), StateError);
  auto shot = t->next_shot(500ms);
  ASSERT_TRUE(shot);
  // Stop in the middle of the playback, once two double pulses have completed (polled for up to
  // 0.5 s rather than a fixed sleep of 60 ms: under load the playback thread may be late).
  for (int i = 0; i < 500 && t->counters().shots_fired < 2; ++i) std::this_thread::sleep_for(1ms);
  t->stop();
  // The measured dt is what really happened (a late Q-switch 1 shortens it): the sync stamps of
  // shot 0's own Q-switch edges, exactly.
  std::uint64_t q1 = 0, q2 = 0;
  for (const RecordedEdge& e : sim->edges()) {
    if (e.shot != 0 || !e.level) continue;
    if (e.line == TriggerLine::QSwitch1) q1 = e.sync_ns;
    if (e.line == TriggerLine::QSwitch2) q2 = e.sync_ns;
  }
  EXPECT_EQ(shot->shot_index, 0u);
  EXPECT_GT(shot->dt_s(), 0);
  EXPECT_EQ(shot->pulse1_ns, q1);
  EXPECT_EQ(shot->pulse2_ns, q2);
  EXPECT_FALSE(t->running());
  for (TriggerLine l : kTriggerLines) EXPECT_FALSE(sim->level(l)) << to_string(l);
  const TriggerCounters c = t->counters();
  EXPECT_GE(c.shots_fired, 2u);
  EXPECT_GE(c.edges_written, 20u);
  for (const RecordedEdge& e : sim->edges()) EXPECT_GE(e.actual_s, e.planned_s);
  t->stop();  // again: harmless
}

TEST(SimTrigger, RefusesSchedulesTighterThanItsJitterAndUnwiredLines) {
  auto t = open_trigger("sim://?uncertainty_us=2000");
  try {
    t->load(fast_schedule());
    FAIL();
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("hardware-timed mode"), std::string::npos) << e.what();
  }
  EXPECT_THROW(t->start(1), StateError);  // nothing loaded
}

TEST(GpioLineMap, ParsesTheUriAndNamesEveryMistake) {
  const GpioLineMap m = parse_gpio_line_map(
      DeviceUri::parse("gpiod://gpiochip0?flashlamp1=17&qswitch1=18&flashlamp2=19&qswitch2=20&camera=27&qsync=22"));
  EXPECT_EQ(m.chip, "gpiochip0");
  EXPECT_EQ(m.outputs.at(TriggerLine::Camera), 27u);
  EXPECT_EQ(m.outputs.at(TriggerLine::QSwitch2), 20u);
  EXPECT_EQ(m.outputs.size(), 5u);
  EXPECT_EQ(*m.qsync, 22u);
  auto error = [](const std::string& uri) {
    try {
      parse_gpio_line_map(DeviceUri::parse(uri));
    } catch (const InputError& e) {
      return std::string(e.what());
    }
    return std::string();
  };
  EXPECT_NE(error("gpiod://gpiochip0?camera=17&qswitch1=17").find("line 17 is given to both qswitch1 and camera"),
            std::string::npos);
  EXPECT_NE(error("gpiod://gpiochip0?camera=-1").find("not a line number"), std::string::npos);
  EXPECT_NE(error("gpiod://gpiochip0?camera=x").find("'camera' must be an integer"), std::string::npos);
  EXPECT_NE(error("gpiod://gpiochip0?flashlamp=3").find("unknown parameter 'flashlamp'"), std::string::npos);
  EXPECT_NE(error("gpiod://gpiochip0?qsync=3").find("no output line given"), std::string::npos);
  EXPECT_NE(error("gpiod://?camera=3").find("needs a chip"), std::string::npos);
  // A chip, never another file: URIs may come from control requests.
  EXPECT_EQ(parse_gpio_line_map(DeviceUri::parse("gpiod:///dev/gpiochip3?camera=1")).chip, "/dev/gpiochip3");
  for (const char* uri : {"gpiod:///etc/shadow?camera=1", "gpiod://../../etc/shadow?camera=1",
                          "gpiod:///dev/zero?camera=1", "gpiod://gpiochip?camera=1", "gpiod://gpiochip0x?camera=1"}) {
    EXPECT_NE(error(uri).find("is not a GPIO chip: give gpiochipN or /dev/gpiochipN"), std::string::npos)
        << uri << ": " << error(uri);
  }
  try {
    check_gpio_lines(m, 24, "gpiod://gpiochip0?...");
    FAIL();
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("line 27 (camera) does not exist on gpiochip0, which has "
                                         "lines 0..23"),
              std::string::npos)
        << e.what();
  }
  EXPECT_NO_THROW(check_gpio_lines(m, 54, "x"));
}

#ifdef PLENOPIV_TEST_HAVE_GPIOD
TEST(GpiodTrigger, AnUnknownChipIsAClearError) {
  const std::string m = open_error("gpiod://gpiochip97?camera=1");
  EXPECT_NE(m.find("cannot open GPIO chip 'gpiochip97'"), std::string::npos) << m;
}

bool have_gpio_chip() {
  std::error_code ec;
  for (const auto& e : std::filesystem::directory_iterator("/dev", ec)) {
    if (e.path().filename().string().rfind("gpiochip", 0) == 0) return true;
  }
  return false;
}

TEST(GpiodTrigger, DrivesARealChip) {
  if (!have_gpio_chip()) GTEST_SKIP() << "no /dev/gpiochip* on this machine (needs a GPIO chip or gpio-sim)";
  // A line number no chip has: refused before any line is requested.
  const std::string m = open_error("gpiod://gpiochip0?camera=1000");
  EXPECT_NE(m.find("does not exist on gpiochip0"), std::string::npos) << m;
}
#else
TEST(GpiodTrigger, NotBuiltIsAClearError) {
  EXPECT_NE(open_error("gpiod://gpiochip0?camera=1").find("PLENOPIV_WITH_GPIOD=ON"), std::string::npos);
}
#endif

}  // namespace
}  // namespace plenopiv::drivers
