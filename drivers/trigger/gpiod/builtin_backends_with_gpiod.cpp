// Built-in trigger backends when libgpiod is built: `gpiod://` drives GPIO lines.
#include "drivers/trigger/gpiod/gpiod_trigger.hpp"
#include "drivers/trigger/trigger_registry.hpp"

namespace plenopiv::drivers {

void register_builtin_trigger_backends(TriggerRegistry& registry) {
  registry.add("gpiod", [](const DeviceUri& uri) { return open_gpiod_trigger(uri); });
}

}  // namespace plenopiv::drivers
