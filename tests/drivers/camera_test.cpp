// The camera interface over the test camera: state machine, registry errors, faults, conformance.
#include <gtest/gtest.h>

#include "core/base/errors.hpp"
#include "drivers/camera/camera_registry.hpp"
#include "drivers/common/driver_errors.hpp"
#include "tests/drivers/camera_conformance.hpp"
#include "tests/drivers/test_camera.hpp"

namespace plenopiv::drivers {
namespace {

using namespace std::chrono_literals;
using testing_support::TestCamera;

std::string open_error(CameraRegistry& registry, const std::string& uri) {
  try {
    registry.open(uri);
  } catch (const InputError& e) {
    return e.what();
  }
  return "";
}

TEST(CameraRegistry, UnknownMalformedAndUnavailableSchemesAreClearErrors) {
  CameraRegistry& r = CameraRegistry::instance();
  const std::string unknown = open_error(r, "gige://cam1");
  EXPECT_NE(unknown.find("unknown camera scheme 'gige'"), std::string::npos) << unknown;
  EXPECT_NE(unknown.find("aravis"), std::string::npos) << unknown;
  EXPECT_NE(open_error(r, "cam1").find("expected <scheme>://"), std::string::npos);
  const std::string sim = open_error(r, "sim://?seed=1");
  if (!r.available("sim")) {
    EXPECT_NE(sim.find("camera backend 'sim' is not available"), std::string::npos) << sim;
  }
#ifndef PLENOPIV_TEST_HAVE_ARAVIS
  const std::string aravis = open_error(r, "aravis://127.0.0.1");
  EXPECT_NE(aravis.find("PLENOPIV_WITH_ARAVIS=ON"), std::string::npos) << aravis;
#endif
}

TEST(CameraRegistry, OpensARegisteredBackendByUri) {
  CameraRegistry r;
  testing_support::register_test_camera(r);
  auto camera = r.open("test://one?lose=3");
  ASSERT_TRUE(camera);
  EXPECT_EQ(camera->info().uri, "test://one?lose=3");
  EXPECT_NE(open_error(r, "test://?loose=3").find("unknown parameter 'loose'"), std::string::npos);
}

TEST(Camera, WrongStateCallsAreRefused) {
  TestCamera cam;
  EXPECT_THROW(cam.start(), StateError);
  EXPECT_THROW(cam.software_trigger(), StateError);
  EXPECT_FALSE(cam.next_pair(1s));  // not running: returns at once
  cam.arm({TriggerSource::Software, 0});
  cam.start();
  EXPECT_THROW(cam.configure({}), StateError);
  EXPECT_THROW(cam.arm({}), StateError);
  EXPECT_THROW(cam.start(), StateError);
  cam.stop();
  cam.stop();
  EXPECT_EQ(cam.status().state, CameraState::Armed);
}

TEST(Camera, BadSettingsNameTheSetting) {
  TestCamera cam;
  CameraSettings s;
  s.roi = {60, 0, 10, 10};
  try {
    cam.configure(s);
    FAIL();
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("roi 60,0 10x10 does not fit the 64x48 sensor"), std::string::npos)
        << e.what();
  }
  s = {};
  s.exposure_s = 0;
  EXPECT_THROW(cam.configure(s), InputError);
  EXPECT_THROW(pixel_format_from_string("Mono10"), InputError);
  EXPECT_EQ(pixel_format_from_string("Mono12"), PixelFormat::Mono12);
  // A pair gap too long to convert to nanoseconds is refused at arm, naming it.
  cam.configure({});
  try {
    cam.arm({TriggerSource::Software, 1e300});
    FAIL();
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("max_pair_gap_s must be within 0..10 s"), std::string::npos) << e.what();
  }
}

TEST(Camera, DeliversTheRightFramesAndCountsFaults) {
  testing_support::TestCameraFaults faults;
  faults.lose = {3};        // B of trigger 1
  faults.incomplete = {4};  // A of trigger 2
  TestCamera cam("test://", faults);
  cam.arm({TriggerSource::Software, 0});
  cam.start();
  for (int i = 0; i < 5; ++i) cam.software_trigger();
  std::vector<FramePair> pairs;
  while (auto p = cam.next_pair(10ms)) pairs.push_back(std::move(*p));
  ASSERT_EQ(pairs.size(), 3u);
  EXPECT_EQ(pairs[0].trigger_index, 0u);
  EXPECT_EQ(pairs[1].trigger_index, 3u);
  EXPECT_EQ(pairs[2].trigger_index, 4u);
  EXPECT_EQ(pairs[1].a.image.at(5, 7), TestCamera::test_pixel(pairs[1].a.frame_id, 5, 7));
  cam.stop();
  const CameraCounters c = cam.counters();
  EXPECT_EQ(c.frames_received, 9u);
  EXPECT_EQ(c.frames_lost, 1u);
  EXPECT_EQ(c.frames_incomplete, 1u);
  EXPECT_EQ(c.pairs_delivered, 3u);
  EXPECT_EQ(c.pairs_discarded, 2u);
  EXPECT_EQ(c.frames_received + c.frames_lost, 2 * 5u);
  EXPECT_EQ(c.frames_received, 2 * c.pairs_delivered + c.frames_discarded);
  // Which triggers gave no pair, and why: 1 lost its frame B (A left unpaired), 2 was incomplete.
  const std::vector<PairDrop> drops = cam.take_drops();
  ASSERT_EQ(drops.size(), 2u);
  EXPECT_EQ(drops[0].trigger_index, 1u);
  EXPECT_EQ(drops[0].reason, PairDrop::Reason::Unpaired);
  EXPECT_EQ(drops[1].trigger_index, 2u);
  EXPECT_EQ(drops[1].reason, PairDrop::Reason::Incomplete);
  EXPECT_TRUE(cam.take_drops().empty()) << "each drop is handed out once";
}

TEST(Camera, SlowConsumerKeepsTheNewestPairsAndCountsTheRest) {
  TestCamera cam;
  cam.arm({TriggerSource::Software, 0});
  cam.start();
  for (int i = 0; i < 20; ++i) cam.software_trigger();
  EXPECT_EQ(cam.counters().pairs_overflowed, 4u);  // queue holds 16
  auto first = cam.next_pair(10ms);
  ASSERT_TRUE(first);
  EXPECT_EQ(first->trigger_index, 4u);
  // The dropped ones are named, so a run's manifest can say which pairs are missing and why.
  const std::vector<PairDrop> drops = cam.take_drops();
  ASSERT_EQ(drops.size(), 4u);
  for (std::uint64_t i = 0; i < 4; ++i) {
    EXPECT_EQ(drops[i].trigger_index, i);
    EXPECT_EQ(drops[i].reason, PairDrop::Reason::QueueOverflow);
  }
  EXPECT_STREQ(to_string(PairDrop::Reason::QueueOverflow), "camera queue overflow");
}

TEST(CameraConformance, TestCamera) {
  TestCamera cam;
  testing_support::ConformanceOptions o;
  o.settings.roi = {8, 4, 32, 16};
  testing_support::check_camera_conformance(cam, o);
}

}  // namespace
}  // namespace plenopiv::drivers
