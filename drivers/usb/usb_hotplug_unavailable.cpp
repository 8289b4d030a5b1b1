// The USB hotplug watcher when libusb is not built: constructing it says so.
#include "drivers/usb/usb_hotplug.hpp"

namespace plenopiv::drivers {

struct UsbHotplugWatcher::Impl {};

UsbHotplugWatcher::UsbHotplugWatcher(Callback) {
  require_usb_hotplug(false,
                      "this build has no USB backend (configure with -DPLENOPIV_WITH_USB=ON "
                      "and install libusb-1.0-0-dev)");
}

UsbHotplugWatcher::~UsbHotplugWatcher() = default;

}  // namespace plenopiv::drivers
