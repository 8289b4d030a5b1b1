// Fuzz target: device URIs as run configs and requests bring them (drivers/common/device_uri), and
// the backends that read one without touching a device: the simulated camera and trigger, and the
// gpiod line map.
#include <algorithm>

#include "drivers/common/device_uri.hpp"
#include "drivers/sim/sim_camera.hpp"
#include "drivers/trigger/gpiod/line_map.hpp"
#include "drivers/trigger/sim_trigger.hpp"
#include "tests/fuzz/seed_camera.hpp"

using namespace plenopiv;

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string text = fuzzing::as_text(data, size);
  drivers::DeviceUri uri;
  try {
    uri = drivers::DeviceUri::parse(text);
  } catch (const InputError& e) {
    // Quoted whole when it is plain text; other bytes are refused and quoted escaped.
    const bool plain = std::all_of(text.begin(), text.end(), [](char c) { return c >= 0x20 && c < 0x7f; });
    fuzzing::require_names(e, plain ? "device URI '" + text + "'" : std::string("device URI '"));
    return 0;
  }
  fuzzing::require(uri.text() == text && !uri.scheme().empty(), "a parsed URI lost its text or scheme");
  const drivers::DeviceUri again = drivers::DeviceUri::parse(uri.text());
  fuzzing::require(again.scheme() == uri.scheme() && again.target() == uri.target() && again.params() == uri.params(),
                   "a URI parsed twice reads differently");
  for (const auto& [key, value] : uri.params()) {
    fuzzing::require(!key.empty() && uri.param(key) == value, "a parameter reads back differently");
    try {
      (void)uri.integer(key);
    } catch (const InputError& e) {
      fuzzing::require_names(e, key);
    }
    try {
      (void)uri.number_or(key, 0.0);
    } catch (const InputError& e) {
      fuzzing::require_names(e, key);
    }
  }
  try {
    if (uri.scheme() == "sim") {
      // Opened, not started: the camera's render thread waits for triggers that never come.
      (void)drivers::open_sim_camera(uri, fuzzing::seed_camera_file());
      (void)drivers::open_sim_trigger(uri);
    } else if (uri.scheme() == "gpiod") {
      const drivers::GpioLineMap map = drivers::parse_gpio_line_map(uri);
      fuzzing::require(!map.chip.empty() && !map.outputs.empty(), "a gpiod line map without chip or outputs");
      drivers::check_gpio_lines(map, 64, uri.text());
    }
  } catch (const InputError& e) {
    fuzzing::require_names(e, "device URI '" + text + "'");
  }
  return 0;
}
