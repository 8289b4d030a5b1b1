// Which GPIO line offset drives which trigger line: parsed from a gpiod:// URI and checked. Pure.
#pragma once

#include <map>
#include <optional>
#include <string>

#include "drivers/common/device_uri.hpp"
#include "drivers/trigger/sequencer.hpp"

namespace plenopiv::drivers {

struct GpioLineMap {
  std::string chip;                         // gpiochip0, or a path /dev/gpiochip0
  std::map<TriggerLine, unsigned> outputs;  // e.g. camera → 27
  std::optional<unsigned> qsync;            // input: the laser's Q-switch sync output
};

// `gpiod://<chip>?flashlamp1=..&qswitch1=..&flashlamp2=..&qswitch2=..&camera=..&gate=..&qsync=..`.
// InputError for a missing chip, no output line, a key that is not a line, a line that is not a
// number or is used twice (both keys named).
GpioLineMap parse_gpio_line_map(const DeviceUri& uri);

// Checks every offset against the chip's line count before any line is requested; the error
// names the key, the line and the chip.
void check_gpio_lines(const GpioLineMap& map, unsigned chip_lines, const std::string& uri);

}  // namespace plenopiv::drivers
