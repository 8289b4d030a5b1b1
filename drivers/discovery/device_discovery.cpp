// Lists the devices plenopiv can drive on this machine: GenICam cameras, USB3 Vision, GPIO chips.
#include "drivers/discovery/device_discovery.hpp"

#include <cstdio>
#include <filesystem>

#ifdef PLENOPIV_HAVE_ARAVIS
#include <arv.h>
#endif
#ifdef PLENOPIV_HAVE_GPIOD
#include <gpiod.h>
#endif
#ifdef PLENOPIV_HAVE_USB
#include <libusb.h>
#endif

namespace plenopiv::drivers {
namespace {

#ifdef PLENOPIV_HAVE_ARAVIS
void add_aravis(DiscoveryReport& report) {
  arv_update_device_list();
  const unsigned n = arv_get_n_devices();
  for (unsigned i = 0; i < n; ++i) {
    const char* id = arv_get_device_id(i);
    const char* model = arv_get_device_model(i);
    const char* protocol = arv_get_device_protocol(i);
    const char* address = arv_get_device_address(i);
    report.devices.push_back({std::string("aravis://") + (id ? id : "?"), "camera", model ? model : "",
                              std::string(protocol ? protocol : "") + (address ? std::string(" ") + address : "")});
  }
}
#endif

#ifdef PLENOPIV_HAVE_GPIOD
void add_gpio_chips(DiscoveryReport& report) {
  std::error_code ec;
  for (const auto& entry : std::filesystem::directory_iterator("/dev", ec)) {
    const std::string name = entry.path().filename().string();
    if (name.rfind("gpiochip", 0) != 0) continue;
    gpiod_chip* chip = gpiod_chip_open(entry.path().c_str());
    if (!chip) {
      report.devices.push_back({"gpiod://" + name, "trigger", "",
                                "present but cannot be opened "
                                "(permissions: install systemd/60-plenopiv.rules)"});
      continue;
    }
    report.devices.push_back(
        {"gpiod://" + name, "trigger", gpiod_chip_label(chip), std::to_string(gpiod_chip_num_lines(chip)) + " lines"});
    gpiod_chip_close(chip);
  }
}
#endif

#ifdef PLENOPIV_HAVE_USB
// USB3 Vision devices carry a Miscellaneous-class interface with subclass 0x05 (U3V).
void add_usb3_vision(DiscoveryReport& report) {
  libusb_context* ctx = nullptr;
  if (libusb_init(&ctx) != 0) return;
  libusb_device** list = nullptr;
  const ssize_t n = libusb_get_device_list(ctx, &list);
  for (ssize_t i = 0; i < n; ++i) {
    libusb_config_descriptor* config = nullptr;
    if (libusb_get_active_config_descriptor(list[i], &config) != 0) continue;
    bool u3v = false;
    for (int k = 0; k < config->bNumInterfaces && !u3v; ++k) {
      const libusb_interface& itf = config->interface[k];
      for (int a = 0; a < itf.num_altsetting; ++a) {
        u3v = u3v || (itf.altsetting[a].bInterfaceClass == 0xEF && itf.altsetting[a].bInterfaceSubClass == 0x05);
      }
    }
    libusb_free_config_descriptor(config);
    if (!u3v) continue;
    libusb_device_descriptor desc{};
    libusb_get_device_descriptor(list[i], &desc);
    char ids[32];
    std::snprintf(ids, sizeof ids, "%04x:%04x", desc.idVendor, desc.idProduct);
    report.devices.push_back({"usb://" + std::string(ids), "usb", "USB3 Vision device",
                              "bus " + std::to_string(libusb_get_bus_number(list[i])) + " address " +
                                  std::to_string(libusb_get_device_address(list[i]))});
  }
  if (list) libusb_free_device_list(list, 1);
  libusb_exit(ctx);
}
#endif

}  // namespace

DiscoveryReport discover_devices() {
  DiscoveryReport report;
#ifdef PLENOPIV_HAVE_ARAVIS
  add_aravis(report);
#else
  report.backends_not_built.push_back("aravis (PLENOPIV_WITH_ARAVIS=OFF)");
#endif
#ifdef PLENOPIV_HAVE_GPIOD
  add_gpio_chips(report);
#else
  report.backends_not_built.push_back("gpiod (PLENOPIV_WITH_GPIOD=OFF)");
#endif
#ifdef PLENOPIV_HAVE_USB
  add_usb3_vision(report);
#else
  report.backends_not_built.push_back("usb (PLENOPIV_WITH_USB=OFF)");
#endif
  return report;
}

}  // namespace plenopiv::drivers
