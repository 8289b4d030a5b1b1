// Built-in trigger backends when libgpiod is not built: `gpiod://` says so and how to get it.
#include "drivers/trigger/trigger_registry.hpp"

namespace plenopiv::drivers {

void register_builtin_trigger_backends(TriggerRegistry& registry) {
  registry.add_unavailable("gpiod",
                           "this build has no GPIO backend (configure with "
                           "-DPLENOPIV_WITH_GPIOD=ON and install libgpiod-dev)");
}

}  // namespace plenopiv::drivers
