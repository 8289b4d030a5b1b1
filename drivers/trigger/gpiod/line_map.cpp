// Which GPIO line offset drives which trigger line: parsed from a gpiod:// URI and checked. Pure.
#include "drivers/trigger/gpiod/line_map.hpp"

#include "core/base/errors.hpp"

namespace plenopiv::drivers {

GpioLineMap parse_gpio_line_map(const DeviceUri& uri) {
  uri.reject_unknown({"flashlamp1", "qswitch1", "flashlamp2", "qswitch2", "camera", "gate", "qsync"});
  GpioLineMap map;
  map.chip = uri.target();
  if (map.chip.empty()) uri.fail("needs a chip, e.g. gpiod://gpiochip0?camera=27");
  // A chip name or its /dev path, nothing else: a URI may come from a request and must not make
  // the daemon open any other file.
  const std::string name = map.chip.rfind("/dev/", 0) == 0 ? map.chip.substr(5) : map.chip;
  const bool chip_name = name.size() > 8 && name.rfind("gpiochip", 0) == 0 && name.size() <= 12 &&
                         name.find_first_not_of("0123456789", 8) == std::string::npos;
  if (!chip_name) {
    uri.fail("'" + map.chip + "' is not a GPIO chip: give gpiochipN or /dev/gpiochipN");
  }
  std::map<long long, std::string> used;
  auto line = [&](const std::string& key) -> std::optional<unsigned> {
    if (!uri.has(key)) return std::nullopt;
    const long long offset = uri.integer(key);
    if (offset < 0 || offset > 1023) {
      uri.fail("line " + key + "=" + std::to_string(offset) + " is not a line number (0..1023)");
    }
    if (auto [it, fresh] = used.emplace(offset, key); !fresh) {
      uri.fail("line " + std::to_string(offset) + " is given to both " + it->second + " and " + key);
    }
    return unsigned(offset);
  };
  for (TriggerLine l : kTriggerLines) {
    if (auto offset = line(to_string(l))) map.outputs[l] = *offset;
  }
  map.qsync = line("qsync");
  if (map.outputs.empty()) {
    uri.fail("no output line given (keys: flashlamp1, qswitch1, flashlamp2, qswitch2, camera, gate)");
  }
  return map;
}

void check_gpio_lines(const GpioLineMap& map, unsigned chip_lines, const std::string& uri) {
  auto check = [&](const std::string& key, unsigned offset) {
    if (offset >= chip_lines) {
      throw InputError("device URI '" + uri + "': line " + std::to_string(offset) + " (" + key +
                       ") does not exist on " + map.chip + ", which has lines 0.." + std::to_string(chip_lines - 1));
    }
  };
  for (const auto& [l, offset] : map.outputs) check(to_string(l), offset);
  if (map.qsync) check("qsync", *map.qsync);
}

}  // namespace plenopiv::drivers
