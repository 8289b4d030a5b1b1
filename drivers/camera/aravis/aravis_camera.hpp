// `aravis://<device-id or address>`: GenICam cameras (GigE Vision, USB3 Vision) through Aravis 0.8.
#pragma once

#include <memory>

#include "drivers/camera/camera.hpp"
#include "drivers/common/device_uri.hpp"

namespace plenopiv::drivers {

// URI parameters (all optional):
//   profile=<name or file>   double-exposure profile (default sfnc-burst; see profiles/)
//   packet_size=<bytes>      GigE Vision stream packet size (e.g. 8000 on loopback or jumbo frames)
//   socket_buffer=<bytes>    receive socket buffer of the stream (default: Aravis sizes it)
//   buffers=<n>              stream buffers (default 16)
//   resend=on|off            ask the camera to resend lost packets (default on)
//   reconnect_s=<seconds>    how often to try to reopen a lost camera (default 1)
// Throws InputError for a malformed URI, a camera that is not found, or a profile naming features
// the camera lacks (every missing feature named).
std::unique_ptr<Camera> open_aravis_camera(const DeviceUri& uri);

}  // namespace plenopiv::drivers
