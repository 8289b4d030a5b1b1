// Built-in camera backends when Aravis is not built: `aravis://` says so and how to get it.
#include "drivers/camera/camera_registry.hpp"

namespace plenopiv::drivers {

void register_builtin_camera_backends(CameraRegistry& registry) {
  registry.add_unavailable("aravis",
                           "this build has no GenICam backend (configure with "
                           "-DPLENOPIV_WITH_ARAVIS=ON and install libaravis-dev)");
}

}  // namespace plenopiv::drivers
