// How a trigger's camera line reaches the camera: a cable, a simulated wire, or nothing (software).
#pragma once

#include <string>

#include "drivers/camera/camera.hpp"
#include "drivers/trigger/trigger.hpp"

namespace plenopiv::drivers {

struct CameraWiring {
  // External: the trigger's camera line fires the camera (arm it so). Software: this trigger
  // cannot reach this camera; whoever runs them must fire software triggers, unsynchronised
  // with the laser, and say so.
  TriggerSource source = TriggerSource::External;
  std::string description;  // one line for logs and manifests
};

// Wires `trigger` to `camera` the way the rig is wired:
//  - a simulated camera (Camera::trigger_input()) and a trigger that can drive it (sim://): the
//    camera line is connected to the camera's input: External, "simulated line";
//  - a real camera and a hardware trigger: the cable from the camera line (or, in hardware-timed
//    mode, the delay generator) to the camera's trigger input: External;
//  - a simulated camera and a hardware trigger, or a real camera and the sim trigger: no line can
//    reach the camera: Software, with the reason.
// The connection lasts until the trigger is destroyed or connect_camera_input(nullptr).
CameraWiring wire_camera(Trigger& trigger, Camera& camera);

}  // namespace plenopiv::drivers
