// USB3 Vision recognition and the messages of the hotplug watcher; pure, built with or without libusb.
#include <cstdio>

#include "drivers/common/driver_errors.hpp"
#include "drivers/usb/usb_hotplug.hpp"

namespace plenopiv::drivers {

bool is_usb3_vision_interface(std::uint8_t interface_class, std::uint8_t interface_subclass) {
  return interface_class == 0xEF && interface_subclass == 0x05;
}

std::string usb_permission_hint(std::uint16_t vendor_id, std::uint16_t product_id, int bus, int address) {
  char ids[16];
  std::snprintf(ids, sizeof ids, "%04x:%04x", vendor_id, product_id);
  return std::string("USB3 Vision camera ") + ids + " on bus " + std::to_string(bus) + " address " +
         std::to_string(address) +
         " is present but cannot be opened (permission denied). Install the udev rule: "
         "sudo cp systemd/60-plenopiv.rules /etc/udev/rules.d/ && sudo udevadm control --reload "
         "&& sudo udevadm trigger, then replug the camera";
}

void require_usb_hotplug(bool supported, const std::string& why) {
  if (supported) return;
  throw DeviceError("USB hotplug is not available (" + why +
                    "): cameras plugged in later are only found when devices are listed again "
                    "(plenopiv devices)");
}

}  // namespace plenopiv::drivers
