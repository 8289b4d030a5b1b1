// The simulated plenoptic camera, `sim://`: each trigger renders a particle pair with core/sim.
#pragma once

#include <filesystem>
#include <memory>

#include "drivers/camera/camera.hpp"
#include "drivers/camera/camera_registry.hpp"
#include "drivers/common/device_uri.hpp"

namespace plenopiv::drivers {

// Opens `sim://?key=value&...`, rendering the camera of `camera_file` (the daemon's camera file:
// a URI, which may come from a request, never names a file). Parameters (all optional):
//   seed=<n>            random seed; pair k uses (seed, k): a run is reproducible (default 1)
//   ppm=<x>             particles per microlens over the field of view (default 0.05)
//   depth_mm=<d>        particles fill z in [-d, d], 0 < d <= 1000 (default 5)
//   flow=uniform|ring|rotation|shear                      (default uniform)
//   dx_mm, dy_mm, dz_mm displacement of the uniform flow (default 0.25, 0, 0)
//   voxel_mm=<v>        voxel edge the ring vortex is defined in (default: the nominal voxel)
//   angle_deg=<a>       rotation about the y axis through the origin (default 1)
//   shear_per_mm=<s>    x displacement per mm of y (default 0.02)
//   rays=<n>            rays per particle (default 2000)
//   brightness_spread=<s> each particle's light a log-normal factor of mean 1 whose log has this
//                       spread, as a real seeding's sizes differ; kept by the particle in both
//                       frames of a pair (0..3, default 0: every particle alike)
//   noise=0|1           shot and read noise, dark offset, 12-bit output (default 0)
//   tap_offset=<counts> with noise=1: the sensor's right half read out this many counts higher, as
//                       a two-tap CCD's second tap (0..1000, default 0)
//   drop_every=<n>      fault: frame B of every n-th trigger never arrives
//   incomplete_every=<n> fault: frame B of every n-th trigger arrives incomplete
//   disconnect_after=<n> fault: the camera is lost after n triggers (status Lost)
//   fail_after=<n>      fault: rendering trigger n throws (the camera fails for good, as an
//                       out-of-memory render would)
//   flow_dt_us=<us>     the pulse separation the flow's displacements belong to; a trigger that
//                       reports another scales them (default 100)
//   readout_ms=<ms>     a pair is rendered this long after its trigger, when frame B would have
//                       been read out, not while the trigger times the laser pulses (default 10)
//   array_rotation_rad=<r> the true lens array turned by r (counter-clockwise, |r| <= 0.1) from the
//                       camera file's nominal lattice: frames that need a calibration (default 0)
// Armed for TriggerSource::External, the camera is fired by rising edges on its trigger_input()
// (a simulated trigger's camera line, drivers/trigger/camera_wiring.hpp); for Software, by
// software_trigger().
// A render that fails (e.g. out of memory) fails the camera (CameraStatus::failed) with the reason.
// Unknown parameters, `camera=`, no camera file, frames larger than this machine's memory, or bad
// values are an InputError naming the URI.
std::unique_ptr<Camera> open_sim_camera(const DeviceUri& uri, const std::filesystem::path& camera_file);

// Registers `sim` in `registry`, rendering `camera_file`. plenopivd does so only when its config
// enables simulation (`simulation: true`).
void register_sim_camera(CameraRegistry& registry, const std::filesystem::path& camera_file);

}  // namespace plenopiv::drivers
