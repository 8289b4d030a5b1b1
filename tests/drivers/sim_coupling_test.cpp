// The seam between the sim trigger and a simulated camera: the camera line's edges make the pairs,
// and the measured laser pulses are attached to each pair.
#include <gtest/gtest.h>

#include "drivers/trigger/camera_wiring.hpp"
#include "drivers/trigger/shot_joiner.hpp"
#include "drivers/trigger/sim_trigger.hpp"
#include "drivers/trigger/trigger_registry.hpp"
#include "tests/drivers/test_camera.hpp"

namespace plenopiv::drivers {
namespace {

using namespace std::chrono_literals;

TEST(SimCoupling, TheSimTriggersCameraLineDrivesTheCameraAndDtIsAttached) {
  testing_support::TestCamera camera;
  camera.arm({TriggerSource::External, 0});
  camera.start();
  auto trigger = open_trigger("sim://?clock=virtual");
  auto* sim = dynamic_cast<SimTrigger*>(trigger.get());
  ASSERT_NE(sim, nullptr);
  // What the simulated camera does when it is coupled: a rising camera edge makes one pair.
  sim->set_edge_listener([&](const RecordedEdge& e) {
    if (e.line == TriggerLine::Camera && e.level) camera.fire();
  });
  TimingRequest r;
  r.pulse_separation_s = 2e-3;
  r.camera_pretrigger_s = 1e-3;
  r.exposure_a_s = 1.5e-3;
  trigger->load(make_schedule(r, {}, 0));
  trigger->start(4);
  ShotJoiner joiner;
  for (int i = 0; i < 4; ++i) {
    auto shot = trigger->next_shot(1s);
    ASSERT_TRUE(shot);
    joiner.add_shot(*shot);
  }
  for (std::uint64_t i = 0; i < 4; ++i) {
    auto pair = camera.next_pair(1s);
    ASSERT_TRUE(pair);
    EXPECT_EQ(pair->trigger_index, i);
    ASSERT_TRUE(joiner.attach(*pair));
    ASSERT_TRUE(pair->measured);
    EXPECT_NEAR(pair->measured->dt_s(), 2e-3, 1e-9);
  }
  camera.stop();
  EXPECT_EQ(camera.counters().pairs_delivered, 4u);
}

// wire_camera connects the camera line to the camera's trigger input, as the daemon does.
TEST(SimCoupling, WireCameraConnectsTheCameraLineToASimulatedCamerasInput) {
  testing_support::TestCamera camera;
  auto trigger = open_trigger("sim://?clock=virtual");
  const CameraWiring wiring = wire_camera(*trigger, camera);
  EXPECT_EQ(wiring.source, TriggerSource::External);
  EXPECT_NE(wiring.description.find("simulated line"), std::string::npos) << wiring.description;
  camera.arm({wiring.source, 0});
  camera.start();
  TimingRequest r;
  r.pulse_separation_s = 2e-3;
  r.camera_pretrigger_s = 1e-3;
  r.exposure_a_s = 1.5e-3;
  trigger->load(make_schedule(r, {}, 0));
  trigger->start(3);
  for (std::uint64_t i = 0; i < 3; ++i) {
    auto pair = camera.next_pair(1s);
    ASSERT_TRUE(pair);
    EXPECT_EQ(pair->trigger_index, i);
  }
  EXPECT_FALSE(camera.next_pair(50ms));
  trigger->stop();
  camera.stop();
  EXPECT_EQ(camera.frames_made(), 6u);
}

TEST(SimCoupling, ACameraNoLineReachesIsSoftwareTriggeredAndTheWiringSaysWhy) {
  testing_support::TestCamera camera("test://?input=none", {}, false);
  auto trigger = open_trigger("sim://");
  const CameraWiring wiring = wire_camera(*trigger, camera);
  EXPECT_EQ(wiring.source, TriggerSource::Software);
  EXPECT_NE(wiring.description.find("cannot reach the camera test://?input=none"), std::string::npos)
      << wiring.description;
}

TEST(SimCoupling, EdgesBeforeStartOrForASoftwareArmedCameraAreIgnored) {
  testing_support::TestCamera camera;
  camera.arm({TriggerSource::External, 0});
  camera.trigger_input()->rising_edge();  // armed, not running: a real camera ignores it too
  EXPECT_EQ(camera.frames_made(), 0u);
  camera.arm({TriggerSource::Software, 0});
  camera.start();
  camera.trigger_input()->rising_edge();
  EXPECT_EQ(camera.frames_made(), 0u);
  camera.stop();
}

TEST(ShotJoiner, SkipsShotsWhosePairNeverCameAndLeavesUnknownPairsAlone) {
  ShotJoiner j;
  for (std::uint64_t i = 0; i < 5; ++i) j.add_shot({i, 1000 * i, 1000 * i + 100});
  FramePair p;
  p.trigger_index = 3;  // pairs 0..2 were discarded by the camera
  ASSERT_TRUE(j.attach(p));
  EXPECT_EQ(p.measured->pulse1_ns, 3000u);
  p.trigger_index = 9;
  p.measured.reset();
  EXPECT_FALSE(j.attach(p));
  EXPECT_FALSE(p.measured);
}

}  // namespace
}  // namespace plenopiv::drivers
