// How a trigger's camera line reaches the camera: a cable, a simulated wire, or nothing (software).
#include "drivers/trigger/camera_wiring.hpp"

namespace plenopiv::drivers {

CameraWiring wire_camera(Trigger& trigger, Camera& camera) {
  const TriggerInfo t = trigger.info();
  const CameraInfo c = camera.info();
  if (TriggerInput* input = camera.trigger_input()) {
    if (trigger.connect_camera_input(input)) {
      return {TriggerSource::External,
              "external: camera line of " + t.uri + " -> trigger input of " + c.uri + " (simulated line)"};
    }
    return {TriggerSource::Software, "software: " + c.uri + " is simulated and the camera line of " + t.uri +
                                         " is a physical output that cannot reach it; pairs are not "
                                         "synchronised with the laser"};
  }
  if (t.simulated) {
    return {TriggerSource::Software, "software: the simulated lines of " + t.uri + " cannot reach the camera " + c.uri +
                                         "; pairs are not synchronised with the laser"};
  }
  return {TriggerSource::External, "external: camera line of " + t.uri + " -> trigger input of " + c.uri + " (cable)"};
}

}  // namespace plenopiv::drivers
