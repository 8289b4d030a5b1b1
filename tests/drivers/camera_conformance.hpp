// The conformance suite every camera driver passes: repeated start/stop, N pairs, correct pairing,
// counters that add up. Shared by the test camera (unit) and the Aravis fake camera (integration).
#pragma once

#include <gtest/gtest.h>

#include <chrono>
#include <string>

#include "drivers/camera/camera.hpp"

namespace plenopiv::testing_support {

// Counters in one line, for failure messages.
inline std::string describe(const drivers::CameraCounters& c) {
  return "received " + std::to_string(c.frames_received) + ", incomplete " + std::to_string(c.frames_incomplete) +
         ", lost " + std::to_string(c.frames_lost) + ", discarded " + std::to_string(c.frames_discarded) +
         ", pairs delivered " + std::to_string(c.pairs_delivered) + ", pairs discarded " +
         std::to_string(c.pairs_discarded) + ", resent packets " + std::to_string(c.packets_resent);
}

struct ConformanceOptions {
  int pairs_per_run = 5;
  int runs = 3;
  std::chrono::milliseconds pair_timeout{2000};
  drivers::CameraSettings settings;
};

// Drives `camera` from Idle with software triggers. Adds GoogleTest failures; returns nothing.
inline void check_camera_conformance(drivers::Camera& camera, const ConformanceOptions& options) {
  using namespace drivers;
  const CameraInfo info = camera.info();
  EXPECT_FALSE(info.model.empty());
  EXPECT_GT(info.sensor_width_px, 0);
  EXPECT_GT(info.sensor_height_px, 0);
  EXPECT_EQ(camera.status().state, CameraState::Idle);
  // Calls in the wrong state are refused.
  EXPECT_ANY_THROW(camera.start());
  EXPECT_ANY_THROW(camera.software_trigger());
  EXPECT_NO_THROW(camera.stop());  // always safe

  camera.configure(options.settings);
  camera.arm(DoubleExposureSettings{TriggerSource::Software, 0.0});
  EXPECT_EQ(camera.status().state, CameraState::Armed);

  const CameraCounters before = camera.counters();
  std::uint64_t last_pair_index = 0;
  bool first = true;
  int delivered = 0;
  for (int run = 0; run < options.runs; ++run) {
    camera.start();
    EXPECT_EQ(camera.status().state, CameraState::Running);
    EXPECT_ANY_THROW(camera.configure(options.settings));  // not while running
    std::uint64_t last_trigger = 0;
    for (int i = 0; i < options.pairs_per_run; ++i) {
      camera.software_trigger();
      const auto pair = camera.next_pair(options.pair_timeout);
      ASSERT_TRUE(pair) << "run " << run << " pair " << i << ": no pair within timeout; "
                        << describe(camera.counters());
      ++delivered;
      EXPECT_TRUE(pair->a.complete && pair->b.complete);
      EXPECT_NE(pair->a.frame_id, pair->b.frame_id);
      EXPECT_LE(pair->a.device_timestamp_ns, pair->b.device_timestamp_ns);
      EXPECT_FALSE(pair->a.image.empty());
      EXPECT_EQ(pair->a.image.width, pair->b.image.width);
      EXPECT_EQ(pair->a.image.height, pair->b.image.height);
      if (options.settings.roi.width > 0) {
        EXPECT_EQ(pair->a.image.width, options.settings.roi.width);
      }
      if (!first) {
        EXPECT_GT(pair->pair_index, last_pair_index);
      }
      if (i > 0) {
        EXPECT_GT(pair->trigger_index, last_trigger);
      }
      last_trigger = pair->trigger_index;
      last_pair_index = pair->pair_index;
      first = false;
    }
    camera.stop();
    EXPECT_EQ(camera.status().state, CameraState::Armed);
    EXPECT_FALSE(camera.next_pair(std::chrono::milliseconds(10))) << "a pair after stop";
  }
  const CameraCounters c = camera.counters();
  EXPECT_EQ(c.pairs_delivered - before.pairs_delivered, std::uint64_t(delivered));
  // Every frame that arrived is in a delivered pair or counted discarded.
  EXPECT_EQ(c.frames_received, 2 * c.pairs_delivered + c.frames_discarded);
  EXPECT_EQ(c.frames_lost, 0u);
  EXPECT_EQ(c.frames_incomplete, 0u);
  EXPECT_EQ(c.pairs_overflowed, 0u);
}

}  // namespace plenopiv::testing_support
