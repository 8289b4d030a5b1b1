// The USB hotplug watcher without a device: recognition, messages, a clear error when unsupported.
#include <gtest/gtest.h>

#include <fstream>
#include <sstream>

#include "drivers/common/driver_errors.hpp"
#include "drivers/usb/usb_hotplug.hpp"

namespace plenopiv::drivers {
namespace {

TEST(UsbHotplug, RecognisesUsb3VisionInterfaces) {
  EXPECT_TRUE(is_usb3_vision_interface(0xEF, 0x05));
  EXPECT_FALSE(is_usb3_vision_interface(0xEF, 0x02));  // interface association, not U3V
  EXPECT_FALSE(is_usb3_vision_interface(0x0E, 0x05));  // UVC video
}

TEST(UsbHotplug, APresentButUnopenableCameraNamesTheUdevRule) {
  const std::string m = usb_permission_hint(0x2676, 0xba02, 2, 7);
  EXPECT_NE(m.find("2676:ba02 on bus 2 address 7"), std::string::npos) << m;
  EXPECT_NE(m.find("systemd/60-plenopiv.rules"), std::string::npos) << m;
  std::ifstream rules(std::string(PLENOPIV_SOURCE_DIR) + "/systemd/60-plenopiv.rules");
  ASSERT_TRUE(rules) << "systemd/60-plenopiv.rules is missing";
  std::stringstream text;
  text << rules.rdbuf();
  EXPECT_NE(text.str().find("*:ef05??:*"), std::string::npos);
  EXPECT_NE(text.str().find("gpiochip"), std::string::npos);
}

TEST(UsbHotplug, UnsupportedHotplugIsAClearError) {
  try {
    require_usb_hotplug(false, "libusb built without hotplug");
    FAIL();
  } catch (const DeviceError& e) {
    const std::string m = e.what();
    EXPECT_NE(m.find("USB hotplug is not available (libusb built without hotplug)"), std::string::npos) << m;
    EXPECT_NE(m.find("plenopiv devices"), std::string::npos) << m;
  }
  EXPECT_NO_THROW(require_usb_hotplug(true, ""));
}

// On this machine the watcher either runs (and sees no camera) or says why it cannot.
TEST(UsbHotplug, WatcherStartsOrExplainsWhyNot) {
  try {
    int events = 0;
    UsbHotplugWatcher watcher([&](const UsbDeviceEvent&) { ++events; });
    SUCCEED() << "hotplug watcher running; " << events << " USB3 Vision devices present";
  } catch (const DeviceError& e) {
    EXPECT_NE(std::string(e.what()).find("USB hotplug is not available"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace plenopiv::drivers
