// Lists the devices plenopiv can drive on this machine: GenICam cameras, USB3 Vision, GPIO chips.
#pragma once

#include <string>
#include <vector>

namespace plenopiv::drivers {

struct DiscoveredDevice {
  std::string uri;   // how a run config names it, e.g. aravis://Fake_1, gpiod://gpiochip0
  std::string kind;  // camera, trigger, usb
  std::string model;
  std::string detail;  // protocol, address, line count, or why it cannot be opened
};

struct DiscoveryReport {
  std::vector<DiscoveredDevice> devices;
  std::vector<std::string> backends_not_built;  // e.g. "gpiod (PLENOPIV_WITH_GPIOD=OFF)"
};

// Enumerates every built backend. Never throws for a missing device: an empty list is an answer.
DiscoveryReport discover_devices();

}  // namespace plenopiv::drivers
