// A tiny in-process camera for tests: deterministic images, pairs on demand, faults on request.
#pragma once

#include <atomic>
#include <cstdint>
#include <memory>
#include <set>

#include "drivers/camera/camera_base.hpp"
#include "drivers/camera/camera_registry.hpp"

namespace plenopiv::testing_support {

struct TestCameraFaults {
  std::set<std::uint64_t> lose;        // frame numbers (0, 1, 2, ... since start) never delivered
  std::set<std::uint64_t> incomplete;  // frame numbers delivered with complete = false
};

// The sensor's size, px; `test://?sensor=WxH` (default 64x48).
struct TestCameraSensor {
  int width = 64, height = 48;
};

// Each software_trigger() (or fire()) delivers frames A and B at once, ids counting up from 1,
// device timestamps 1 ms apart within a pair and 100 ms between pairs. Pixel (x, y) of frame id f
// holds test_pixel(f, x, y), so a test can tell which frame it got.
// Armed for External, rising edges on its trigger input fire it too (a simulated trigger's camera
// line); `with_input = false` makes a camera without one (like a real camera on a cable).
class TestCamera : public drivers::CameraBase, public drivers::TriggerInput {
 public:
  explicit TestCamera(std::string uri = "test://", TestCameraFaults faults = {}, bool with_input = true,
                      TestCameraSensor sensor = {});
  static std::uint16_t test_pixel(std::uint64_t frame_id, int x, int y);
  // Fires one trigger, whatever the trigger source (stands in for the trigger line).
  void fire();
  std::uint64_t frames_made() const { return frame_number_; }
  drivers::TriggerInput* trigger_input() override { return with_input_ ? this : nullptr; }
  void rising_edge() override {
    if (external_ && wanted_state() == drivers::CameraState::Running) fire();
  }

 protected:
  void do_configure(const drivers::CameraSettings& settings) override;
  void do_arm(const drivers::DoubleExposureSettings& s) override {
    external_ = s.trigger == drivers::TriggerSource::External;
  }
  void do_start() override { trigger_ = 0; }
  void do_stop() override {}
  void do_software_trigger() override { fire(); }

 private:
  TestCameraFaults faults_;
  bool with_input_;
  std::atomic<bool> external_{false};
  drivers::CameraSettings settings_;
  TestCameraSensor sensor_;
  std::uint64_t frame_number_ = 0;
  std::uint64_t next_id_ = 1;
  std::uint64_t trigger_ = 0;
};

// Registers `test://` in `registry` (faults from the URI: lose=3,7&incomplete=4; input=none: no
// trigger input).
void register_test_camera(drivers::CameraRegistry& registry);

}  // namespace plenopiv::testing_support
