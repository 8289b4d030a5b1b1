// The simulated camera `sim://`: conformance, reproducible frames, injected faults, refused URIs.
#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <string>

#include "core/base/errors.hpp"
#include "drivers/sim/sim_camera.hpp"
#include "tests/drivers/camera_conformance.hpp"

namespace plenopiv::drivers {
namespace {

using namespace std::chrono_literals;

const std::string kCamera = std::string(PLENOPIV_SOURCE_DIR) + "/systemd/config/camera-small.yaml";

std::unique_ptr<Camera> open(const std::string& params) {
  return open_sim_camera(DeviceUri::parse("sim://?rays=200&ppm=0.02&" + params), kCamera);
}

// Starts `camera` with software triggers and fires `n` triggers.
void run_triggers(Camera& camera, int n) {
  camera.configure(CameraSettings{});
  camera.arm(DoubleExposureSettings{TriggerSource::Software, 0.0});
  camera.start();
  for (int i = 0; i < n; ++i) camera.software_trigger();
}

TEST(SimCamera, PassesTheConformanceSuite) {
  auto camera = open("seed=3");
  testing_support::ConformanceOptions o;
  o.pairs_per_run = 3;
  o.runs = 2;
  o.pair_timeout = 20s;
  testing_support::check_camera_conformance(*camera, o);
  EXPECT_EQ(camera->info().sensor_width_px, 850);
}

TEST(SimCamera, TheSameSeedRendersTheSameFrames) {
  auto first = open("seed=7");
  auto second = open("seed=7");
  auto other = open("seed=8");
  for (Camera* c : {first.get(), second.get(), other.get()}) run_triggers(*c, 2);
  for (int k = 0; k < 2; ++k) {
    const auto p1 = first->next_pair(20s), p2 = second->next_pair(20s), p3 = other->next_pair(20s);
    ASSERT_TRUE(p1 && p2 && p3);
    EXPECT_EQ(p1->a.image.pixels, p2->a.image.pixels);
    EXPECT_EQ(p1->b.image.pixels, p2->b.image.pixels);
    EXPECT_NE(p1->a.image.pixels, p3->a.image.pixels);
    EXPECT_NE(p1->a.image.pixels, p1->b.image.pixels);  // B holds the displaced particles
    double lit = 0;
    for (auto v : p1->a.image.pixels) lit += v;
    EXPECT_GT(lit, 0) << "frame A is black";
    EXPECT_EQ(p1->trigger_index, std::uint64_t(k));
  }
}

// A second readout tap's offset: the same frames with the right half `tap_offset` counts higher
// (added before the 12 bits' clamp, as a sensor does: a pixel the first tap read as 0 reads at
// most the offset).
TEST(SimCamera, ASecondTapsOffsetRaisesTheRightHalf) {
  auto one = open("seed=7&noise=1");
  auto two = open("seed=7&noise=1&tap_offset=30");
  for (Camera* c : {one.get(), two.get()}) run_triggers(*c, 1);
  const auto p1 = one->next_pair(20s), p2 = two->next_pair(20s);
  ASSERT_TRUE(p1 && p2);
  const ImageU16 &a1 = p1->a.image, &a2 = p2->a.image;
  for (int y = 0; y < a1.height; ++y)
    for (int x = 0; x < a1.width; ++x)
      if (x < a1.width / 2 || a1.at(x, y) > 0)
        ASSERT_EQ(a2.at(x, y), x < a1.width / 2 ? a1.at(x, y) : std::min(4095, a1.at(x, y) + 30)) << x << ", " << y;
      else
        ASSERT_LE(a2.at(x, y), 30) << x << ", " << y;
}

// Particles that differ in brightness keep it from frame A to frame B: with the scene at rest,
// each frame's light over the same frame without the spread is the same ratio (the particles'
// mean factor), up to the rays' own noise.
TEST(SimCamera, ParticlesOfDifferentBrightnessKeepItInBothFrames) {
  auto spread = open("seed=7&dx_mm=0&brightness_spread=1");
  auto alike = open("seed=7&dx_mm=0");
  auto zero = open("seed=7&dx_mm=0&brightness_spread=0");
  for (Camera* c : {spread.get(), alike.get(), zero.get()}) run_triggers(*c, 1);
  const auto s = spread->next_pair(20s), a = alike->next_pair(20s), z = zero->next_pair(20s);
  ASSERT_TRUE(s && a && z);
  EXPECT_EQ(z->a.image.pixels, a->a.image.pixels);  // a spread of 0 is every particle alike
  auto light = [](const ImageU16& image) {
    double sum = 0;
    for (auto v : image.pixels) sum += v;
    return sum;
  };
  const double ratio_a = light(s->a.image) / light(a->a.image), ratio_b = light(s->b.image) / light(a->b.image);
  EXPECT_NE(s->a.image.pixels, a->a.image.pixels);
  EXPECT_NEAR(ratio_b / ratio_a, 1.0, 0.02) << ratio_a << " " << ratio_b;
  std::printf("light with the spread over without: frame A %.4f, frame B %.4f\n", ratio_a, ratio_b);
}

// Laser pulses reported on the trigger input set how far the scene moves: pulses 200 us apart
// with the flow given for 100 us render what a flow twice as fast renders with none reported.
TEST(SimCamera, TheSceneMovesForTheTimeBetweenTheReportedLaserPulses) {
  auto pulsed = open("seed=5&dx_mm=0.25&flow_dt_us=100");
  auto doubled = open("seed=5&dx_mm=0.5");
  auto plain = open("seed=5&dx_mm=0.25");
  pulsed->configure(CameraSettings{});
  pulsed->arm(DoubleExposureSettings{TriggerSource::External, 0.0});
  pulsed->start();
  TriggerInput* input = pulsed->trigger_input();
  ASSERT_NE(input, nullptr);
  input->rising_edge();
  input->laser_pulse(1'000'000);
  input->laser_pulse(1'200'000);
  run_triggers(*doubled, 1);
  run_triggers(*plain, 1);
  const auto p = pulsed->next_pair(20s), d = doubled->next_pair(20s), n = plain->next_pair(20s);
  ASSERT_TRUE(p && d && n);
  EXPECT_EQ(p->a.image.pixels, d->a.image.pixels);
  EXPECT_EQ(p->b.image.pixels, d->b.image.pixels);
  EXPECT_NE(p->b.image.pixels, n->b.image.pixels);
}

// Frame B follows frame A by a read-out, not by its own render: at paper scale one frame's render
// took longer than the pairer's wait for a B (1 s), and pairs were discarded.
TEST(SimCamera, TheFramesOfAPairArriveTogether) {
  auto camera = open_sim_camera(DeviceUri::parse("sim://?rays=5000&ppm=1&seed=5"), kCamera);
  run_triggers(*camera, 2);
  for (int k = 0; k < 2; ++k) {
    const auto p = camera->next_pair(20s);
    ASSERT_TRUE(p);
    const double gap_ms = double(p->b.host_timestamp_ns - p->a.host_timestamp_ns) * 1e-6;
    std::printf("pair %d: frame B %.3f ms after frame A (host clock)\n", k, gap_ms);
    // Frame B is delivered with frame A, not after a render of its own (which takes 100s of ms).
    EXPECT_LT(gap_ms, 10.0) << "measured 0.002 ms";
  }
  camera->stop();
}

TEST(SimCamera, DroppedFramesDiscardTheirPairAndAreCounted) {
  auto camera = open("drop_every=2");
  run_triggers(*camera, 4);
  int delivered = 0;
  while (camera->next_pair(3s)) ++delivered;
  EXPECT_EQ(delivered, 2);
  const CameraCounters c = camera->counters();
  EXPECT_EQ(c.pairs_delivered, 2u);
  EXPECT_EQ(c.frames_received, 6u) << testing_support::describe(c);
}

TEST(SimCamera, IncompleteFramesAreNeverPaired) {
  auto camera = open("incomplete_every=2");
  run_triggers(*camera, 4);
  int delivered = 0;
  while (auto pair = camera->next_pair(3s)) {
    EXPECT_TRUE(pair->a.complete && pair->b.complete);
    EXPECT_EQ(pair->trigger_index % 2, 0u);
    ++delivered;
  }
  EXPECT_EQ(delivered, 2);
  const CameraCounters c = camera->counters();
  EXPECT_EQ(c.frames_incomplete, 2u) << testing_support::describe(c);
  EXPECT_EQ(c.pairs_discarded, 2u) << testing_support::describe(c);
}

TEST(SimCamera, ADisconnectIsReportedAsLost) {
  auto camera = open("disconnect_after=1");
  run_triggers(*camera, 2);
  EXPECT_TRUE(camera->next_pair(20s));
  EXPECT_FALSE(camera->next_pair(1s));
  const CameraStatus s = camera->status();
  EXPECT_EQ(s.state, CameraState::Lost);
  EXPECT_NE(s.last_error.find("simulated disconnect"), std::string::npos) << s.last_error;
}

TEST(SimCamera, BadUrisAreNamed) {
  auto message = [](const std::string& uri) -> std::string {
    try {
      open_sim_camera(DeviceUri::parse(uri), kCamera);
    } catch (const InputError& e) {
      return e.what();
    }
    return "";
  };
  EXPECT_NE(message("sim://?colour=red").find("colour"), std::string::npos);
  EXPECT_NE(message("sim://?flow=tornado").find("unknown flow 'tornado'"), std::string::npos);
  EXPECT_NE(message("sim://?ppm=-1").find("ppm"), std::string::npos);
  EXPECT_NE(message("sim://?rays=0").find("rays"), std::string::npos);
  EXPECT_NE(message("sim://?flow_dt_us=0").find("flow_dt_us"), std::string::npos);
  EXPECT_NE(message("sim://?tap_offset=30").find("tap_offset: needs noise=1"), std::string::npos);
  EXPECT_NE(message("sim://?noise=1&tap_offset=5000").find("tap_offset: must be in [0, 1000]"), std::string::npos);
  const std::string bright = message("sim://?brightness_spread=5");
  EXPECT_NE(bright.find("sim://?brightness_spread=5"), std::string::npos) << bright;
  EXPECT_NE(bright.find("brightness_spread: the spread of a particle's log light, 0 to 3"), std::string::npos)
      << bright;
  EXPECT_NE(message("sim://?brightness_spread=-1").find("brightness_spread"), std::string::npos);
  // A box of no depth is the URI's error, named with its key, not a geometry failure later.
  const std::string flat = message("sim://?depth_mm=0");
  EXPECT_NE(flat.find("sim://?depth_mm=0"), std::string::npos) << flat;
  EXPECT_NE(flat.find("depth_mm: must be in (0, 1000] mm"), std::string::npos) << flat;
  // A URI may come from a control request: it never names a file for the daemon to open.
  const std::string named_file = message("sim://?camera=/etc/passwd");
  EXPECT_NE(named_file.find("a URI cannot name a file"), std::string::npos) << named_file;
  EXPECT_EQ(named_file.find("root:"), std::string::npos) << named_file;
  EXPECT_NE(message("sim://cam0").find("sim://cam0"), std::string::npos);
}

// Sizes that cannot be allocated are refused with the estimate, before the render thread tries.
TEST(SimCamera, AFrameLargerThanTheMachinesMemoryIsRefusedWithTheEstimate) {
  const auto file =
      std::filesystem::temp_directory_path() / ("plenopiv-huge-camera-" + std::to_string(::getpid()) + ".yaml");
  std::ofstream(file) << "sensor:    {width_px: 1000000000, height_px: 1000000000, pixel_pitch_mm: 0.0074}\n"
                         "microlens: {pitch_mm: 0.125, focal_length_mm: 0.5, count_x: 289, count_y: 193}\n"
                         "main_lens: {focal_length_mm: 50, f_number: 2, magnification: -1}\n";
  try {
    open_sim_camera(DeviceUri::parse("sim://?rays=10"), file);
    FAIL() << "a 10^9 x 10^9 px camera was opened";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("the simulated camera's frames (1000000000 x 1000000000 px"),
              std::string::npos)
        << e.what();
    EXPECT_NE(std::string(e.what()).find("GB of memory"), std::string::npos) << e.what();
  }
  std::filesystem::remove(file);
}

// A render that throws fails the camera with the reason instead of ending the program.
TEST(SimCamera, ARenderFaultFailsTheCameraWithItsReason) {
  auto camera = open("fail_after=1");
  run_triggers(*camera, 2);
  EXPECT_TRUE(camera->next_pair(20s));  // trigger 0 renders
  EXPECT_FALSE(camera->next_pair(2s));  // trigger 1 throws in the render thread
  const CameraStatus s = camera->status();
  EXPECT_TRUE(s.failed);
  EXPECT_EQ(s.state, CameraState::Lost);
  EXPECT_NE(s.last_error.find("simulated render fault"), std::string::npos) << s.last_error;
}

// stop() waits for exposures already triggered only so long: what the camera has not read out by
// then is dropped and named, so a run's stop is bounded whatever the renderer's backlog.
TEST(SimCamera, StopIsBoundedAndNamesWhatWasNotReadOut) {
  auto camera = open("readout_ms=8000");  // each pair rendered 8 s after its trigger
  run_triggers(*camera, 3);
  const auto t0 = std::chrono::steady_clock::now();
  camera->stop();
  const double took = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  EXPECT_LT(took, 5.0) << "stop waited for the whole backlog";
  EXPECT_EQ(camera->counters().pairs_not_read_out, 3u);
  const std::vector<PairDrop> drops = camera->take_drops();
  ASSERT_EQ(drops.size(), 3u);
  for (std::uint64_t i = 0; i < 3; ++i) {
    EXPECT_EQ(drops[i].trigger_index, i);
    EXPECT_EQ(drops[i].reason, PairDrop::Reason::NotReadOut);
  }
  EXPECT_FALSE(camera->next_pair(0ms));
}

TEST(SimCamera, RegistersUnderSim) {
  CameraRegistry registry;
  register_sim_camera(registry, kCamera);
  EXPECT_TRUE(registry.available("sim"));
  auto camera = registry.open("sim://?rays=100");
  EXPECT_EQ(camera->info().model, "simulated plenoptic camera");
}

}  // namespace
}  // namespace plenopiv::drivers
