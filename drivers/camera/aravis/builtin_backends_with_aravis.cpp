// Built-in camera backends when Aravis is built: `aravis://` opens GenICam cameras.
#include "drivers/camera/aravis/aravis_camera.hpp"
#include "drivers/camera/camera_registry.hpp"

namespace plenopiv::drivers {

void register_builtin_camera_backends(CameraRegistry& registry) {
  registry.add("aravis", [](const DeviceUri& uri) { return open_aravis_camera(uri); });
}

}  // namespace plenopiv::drivers
