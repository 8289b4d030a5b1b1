// The replay camera, `replay://`: plays recorded frame pairs (a run folder or a folder of TIFF
// files) through the camera interface, triggered or free-running, at any rate.
#pragma once

#include <cstdint>
#include <filesystem>
#include <memory>

#include "drivers/camera/camera.hpp"
#include "drivers/camera/camera_registry.hpp"
#include "drivers/common/device_uri.hpp"

namespace plenopiv::drivers {

// Where a replay camera may read and what its frames must look like: both fixed by whoever
// registers it (plenopivd: its config), never by the URI, which may come from a request.
struct ReplaySource {
  // The only folder a replay:// URI may read: its target is a path relative to this folder (empty:
  // the folder itself), and after resolving symbolic links it must still lie inside it.
  std::filesystem::path replay_dir;
  // The camera file whose sensor size every frame must have (plenopivd's camera_file).
  std::filesystem::path camera_file;
};

// Default read-ahead budget (MB) for decoded frames: 16 pairs of the paper's 4904 x 3280 sensor
// (a frame is 32 MB, a pair 64 MB).
inline constexpr std::uint64_t kReplayDefaultBufferMb = 1024;

// Opens `replay://<folder>?key=value&...`. The folder (relative to source.replay_dir) is either
//   - a run folder (it holds manifest.json): its pairs, in the manifest's order, read with
//     run_folder::Reader (which validates the manifest and that every frame exists), or
//   - a plain folder of TIFF files: every regular *.tif / *.tiff file in it (not in subfolders),
//     sorted by file name and taken two by two, the first of each two as frame A, the second as B
//     (pair-0-A.tif, pair-0-B.tif, pair-1-A.tif, ... or frame_0001.tif, frame_0002.tif, ...). An
//     odd count is refused naming the file left without a partner.
// Every frame must be an 8- or 16-bit single-channel TIFF of the camera file's sensor size; each is
// checked (header and strips) at open, and a mismatch is an InputError naming the file.
// Parameters (all optional):
//   rate_hz=<Hz>   0 (default): triggered, one recorded pair per trigger (a rising edge on
//                  trigger_input() when armed External, software_trigger() when armed Software),
//                  as the simulated camera; > 0 (at most 1000): free-running, playing a pair every
//                  1/rate_hz s from start() and ignoring triggers, as a camera in free-run mode.
//   loop=0|1       at the end of the recording, play it again from the first pair (default 0:
//                  a free-running camera stops delivering; a trigger after the last pair fails the
//                  camera with "end of the recording", since the trigger cannot be honoured).
//   buffer_mb=<MB> memory for decoded frames (default kReplayDefaultBufferMb, at least two pairs):
//                  when the whole recording fits, it is decoded at the first start() (the caller's
//                  thread: plenopivd's run thread, never the request that opens it) and played from memory;
//                  otherwise a read-ahead thread keeps up to buffer_mb of pairs decoded ahead of
//                  the player. A trigger whose pair is not decoded yet delivers nothing: its two
//                  frames are counted lost (CameraCounters::frames_lost, as any camera's missing
//                  frames) and the recording goes on with that pair at the next trigger.
// Frames carry new ids (2t+1, 2t+2 for trigger t since open, as a camera numbers its frames), the
// device timestamp of their trigger on the replay's clock (free-running: exactly start + k /
// rate_hz; frame B 1 us after A) and the host time they were delivered.
// A pixel read that fails during the replay (a file changed since open) fails the camera
// (CameraStatus::failed) naming the file.
// InputError naming the URI for: unknown parameters, bad values, a folder outside replay_dir (or
// no replay_dir), a missing folder, no frames, a non-regular file, a wrong-sized frame.
std::unique_ptr<Camera> open_replay_camera(const DeviceUri& uri, const ReplaySource& source);

// Registers `replay` in `registry`. plenopivd does so only when its config enables simulation and
// names a replay_dir.
void register_replay_camera(CameraRegistry& registry, const ReplaySource& source);

}  // namespace plenopiv::drivers
