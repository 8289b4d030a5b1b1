// Watches USB for USB3 Vision cameras coming and going, so the daemon can rediscover cameras, and
// says how to fix a camera that is present but cannot be opened (the udev rule to install).
#pragma once

#include <cstdint>
#include <functional>
#include <memory>
#include <string>

namespace plenopiv::drivers {

struct UsbDeviceEvent {
  bool arrived = true;  // false: unplugged
  std::uint16_t vendor_id = 0, product_id = 0;
  int bus = 0, address = 0;
  bool openable = true;  // arrived and could be opened (permissions)
  std::string message;   // what to do when it cannot be opened, else a description
};

// USB3 Vision devices carry an interface of class 0xEF (miscellaneous), subclass 0x05.
bool is_usb3_vision_interface(std::uint8_t interface_class, std::uint8_t interface_subclass);
// The message for a USB3 Vision device the user may not open: names it and the udev rule.
std::string usb_permission_hint(std::uint16_t vendor_id, std::uint16_t product_id, int bus, int address);
// Throws DeviceError with a clear message when hotplug is not available (libusb without hotplug
// support, no /dev/bus/usb in a container): rediscovery then has to be asked for by hand.
void require_usb_hotplug(bool supported, const std::string& why);

// Calls `on_change` (from its own thread) for every USB3 Vision device that arrives or leaves,
// including those present at start. Destroying it stops the thread.
class UsbHotplugWatcher {
 public:
  using Callback = std::function<void(const UsbDeviceEvent&)>;
  explicit UsbHotplugWatcher(Callback on_change);
  ~UsbHotplugWatcher();
  UsbHotplugWatcher(const UsbHotplugWatcher&) = delete;
  UsbHotplugWatcher& operator=(const UsbHotplugWatcher&) = delete;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace plenopiv::drivers
