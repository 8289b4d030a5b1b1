// A tiny in-process camera for tests: deterministic images, pairs on demand, faults on request.
#pragma once

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

// Each software_trigger() (or fire()) delivers frames A and B at once, ids counting up from 1,
// device timestamps 1 ms apart within a pair and 100 ms between pairs. Pixel (x, y) of frame id f
// holds test_pixel(f, x, y), so a test can tell which frame it got.
class TestCamera : public drivers::CameraBase {
 public:
  explicit TestCamera(std::string uri = "test://", TestCameraFaults faults = {});
  static std::uint16_t test_pixel(std::uint64_t frame_id, int x, int y);
  // Fires one trigger, whatever the trigger source (stands in for the trigger line).
  void fire();
  std::uint64_t frames_made() const { return frame_number_; }

 protected:
  void do_configure(const drivers::CameraSettings& settings) override;
  void do_arm(const drivers::DoubleExposureSettings&) override {}
  void do_start() override { trigger_ = 0; }
  void do_stop() override {}
  void do_software_trigger() override { fire(); }

 private:
  TestCameraFaults faults_;
  drivers::CameraSettings settings_;
  std::uint64_t frame_number_ = 0;
  std::uint64_t next_id_ = 1;
  std::uint64_t trigger_ = 0;
};

// Registers `test://` in `registry` (faults from the URI: lose=3,7&incomplete=4).
void register_test_camera(drivers::CameraRegistry& registry);

}  // namespace plenopiv::testing_support
