// The libusb hotplug watcher for USB3 Vision cameras (libusb-1.0 hotplug API, one event thread).
#include <libusb.h>

#include <atomic>
#include <thread>

#include "drivers/common/driver_errors.hpp"
#include "drivers/usb/usb_hotplug.hpp"

namespace plenopiv::drivers {
namespace {

bool usb3_vision(libusb_device* device) {
  libusb_config_descriptor* config = nullptr;
  if (libusb_get_active_config_descriptor(device, &config) != 0 &&
      libusb_get_config_descriptor(device, 0, &config) != 0) {
    return false;
  }
  bool found = false;
  for (int k = 0; k < config->bNumInterfaces && !found; ++k) {
    const libusb_interface& itf = config->interface[k];
    for (int a = 0; a < itf.num_altsetting; ++a) {
      found =
          found || is_usb3_vision_interface(itf.altsetting[a].bInterfaceClass, itf.altsetting[a].bInterfaceSubClass);
    }
  }
  libusb_free_config_descriptor(config);
  return found;
}

}  // namespace

struct UsbHotplugWatcher::Impl {
  Callback on_change;
  libusb_context* context = nullptr;
  libusb_hotplug_callback_handle handle{};
  bool registered = false;
  std::atomic<bool> quit{false};
  std::thread thread;

  // libusb's event thread (C): nothing may throw through it.
  static int LIBUSB_CALL on_event(libusb_context* context, libusb_device* device, libusb_hotplug_event event,
                                  void* self_ptr) noexcept {
    try {
      return handle_event(context, device, event, self_ptr);
    } catch (const std::exception& ex) {
      auto* self = static_cast<Impl*>(self_ptr);
      UsbDeviceEvent e;
      e.arrived = event == LIBUSB_HOTPLUG_EVENT_DEVICE_ARRIVED;
      e.openable = false;
      e.message = std::string("USB event could not be handled: ") + ex.what();
      try {
        self->on_change(e);
      } catch (...) {
      }
      return 0;
    }
  }

  static int handle_event(libusb_context*, libusb_device* device, libusb_hotplug_event event, void* self_ptr) {
    auto* self = static_cast<Impl*>(self_ptr);
    libusb_device_descriptor desc{};
    libusb_get_device_descriptor(device, &desc);
    UsbDeviceEvent e;
    e.arrived = event == LIBUSB_HOTPLUG_EVENT_DEVICE_ARRIVED;
    e.vendor_id = desc.idVendor;
    e.product_id = desc.idProduct;
    e.bus = libusb_get_bus_number(device);
    e.address = libusb_get_device_address(device);
    if (e.arrived) {
      if (!usb3_vision(device)) return 0;
      libusb_device_handle* h = nullptr;
      const int r = libusb_open(device, &h);
      if (r == 0) {
        libusb_close(h);
        e.message = "USB3 Vision camera arrived";
      } else {
        e.openable = false;
        e.message = r == LIBUSB_ERROR_ACCESS
                        ? usb_permission_hint(e.vendor_id, e.product_id, e.bus, e.address)
                        : std::string("USB3 Vision camera cannot be opened: ") + libusb_strerror(r);
      }
    } else {
      e.openable = false;
      e.message = "USB device left";  // descriptors may be gone: let rediscovery decide
    }
    self->on_change(e);
    return 0;  // stay registered
  }
};

UsbHotplugWatcher::UsbHotplugWatcher(Callback on_change) : impl_(std::make_unique<Impl>()) {
  impl_->on_change = std::move(on_change);
  require_usb_hotplug(libusb_has_capability(LIBUSB_CAP_HAS_HOTPLUG) != 0,
                      "this libusb was built without hotplug support");
  if (const int r = libusb_init(&impl_->context); r != 0) {
    impl_->context = nullptr;
    require_usb_hotplug(false, std::string("libusb_init: ") + libusb_strerror(r));
  }
  const int r = libusb_hotplug_register_callback(
      impl_->context,
      static_cast<libusb_hotplug_event>(LIBUSB_HOTPLUG_EVENT_DEVICE_ARRIVED | LIBUSB_HOTPLUG_EVENT_DEVICE_LEFT),
      LIBUSB_HOTPLUG_ENUMERATE, LIBUSB_HOTPLUG_MATCH_ANY, LIBUSB_HOTPLUG_MATCH_ANY, LIBUSB_HOTPLUG_MATCH_ANY,
      &Impl::on_event, impl_.get(), &impl_->handle);
  if (r != LIBUSB_SUCCESS) {
    libusb_exit(impl_->context);
    impl_->context = nullptr;
    require_usb_hotplug(false, std::string("cannot register a hotplug callback: ") + libusb_strerror(r));
  }
  impl_->registered = true;
  impl_->thread = std::thread([impl = impl_.get()] {
    while (!impl->quit) {
      timeval tv{0, 200'000};
      libusb_handle_events_timeout_completed(impl->context, &tv, nullptr);
    }
  });
}

UsbHotplugWatcher::~UsbHotplugWatcher() {
  if (!impl_) return;
  impl_->quit = true;
  if (impl_->registered) libusb_hotplug_deregister_callback(impl_->context, impl_->handle);
  if (impl_->thread.joinable()) impl_->thread.join();
  if (impl_->context) libusb_exit(impl_->context);
}

}  // namespace plenopiv::drivers
