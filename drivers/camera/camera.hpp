// The camera driver interface: open by URI, configure, arm double exposure, deliver FramePairs.
#pragma once

#include <chrono>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "core/base/image.hpp"

namespace plenopiv::drivers {

enum class PixelFormat { Mono8, Mono12, Mono16 };
const char* to_string(PixelFormat format);
// "Mono8", "Mono12" or "Mono16"; anything else is an InputError naming the value.
PixelFormat pixel_format_from_string(const std::string& name);
int bit_depth(PixelFormat format);

struct CameraInfo {
  std::string uri;  // as opened
  std::string vendor;
  std::string model;
  std::string serial;
  int sensor_width_px = 0;
  int sensor_height_px = 0;
  std::string double_exposure;  // how pairs are made, e.g. "burst (sfnc-burst)", "two frames"
};

// Region of interest in sensor pixels; width or height 0 means "the full sensor".
struct Roi {
  int x = 0, y = 0, width = 0, height = 0;
};

struct CameraSettings {
  Roi roi;
  PixelFormat pixel_format = PixelFormat::Mono16;
  double exposure_s = 100e-6;  // frame A exposure; frame B lasts until readout (interline CCD)
  double gain_db = 0.0;
};

enum class TriggerSource {
  External,  // a hardware line (the trigger driver fires it)
  Software,  // software_trigger() fires each pair (tests, and cameras without a wired line)
};

struct DoubleExposureSettings {
  TriggerSource trigger = TriggerSource::External;
  // Largest time between the two frames of one pair (device clock when it has one, else host).
  // Frames further apart are never paired. 0 = the backend's default.
  double max_pair_gap_s = 0.0;
};

// One exposure as delivered. Pixels are widened to 16 bit; `bit_depth` says how many are used.
struct Frame {
  ImageU16 image;
  int bit_depth = 16;
  std::uint64_t frame_id = 0;             // the device's own block/frame id
  std::uint64_t device_timestamp_ns = 0;  // device clock; 0 when the device has none
  std::uint64_t host_timestamp_ns = 0;    // CLOCK_REALTIME when the host received it
  bool complete = true;                   // all data arrived; pairs are only made of complete frames
};

// The laser pulses of a pair as measured on the Q-switch sync input (trigger driver's clock).
struct LaserPulses {
  std::uint64_t pulse1_ns = 0;
  std::uint64_t pulse2_ns = 0;
  double dt_s() const { return double(pulse2_ns - pulse1_ns) * 1e-9; }
};

// Frame A (ends with laser pulse 1) and frame B (holds pulse 2) of one trigger.
struct FramePair {
  std::uint64_t pair_index = 0;     // 0, 1, 2, ... in delivery order since open
  std::uint64_t trigger_index = 0;  // which trigger made it (counted from start; gaps = lost triggers)
  Frame a, b;
  // The dt that really happened, when a trigger measures the Q-switch sync (ShotJoiner fills it).
  std::optional<LaserPulses> measured;
};

// Running totals since open; they never go down. Every frame the device produced is either in a
// delivered pair, counted incomplete, counted lost (never arrived), or in a discarded pair.
struct CameraCounters {
  std::uint64_t frames_received = 0;    // arrived, complete or not
  std::uint64_t frames_incomplete = 0;  // arrived with missing packets, wrong size, or timed out
  std::uint64_t frames_lost = 0;        // never arrived (gaps in frame ids)
  std::uint64_t frames_discarded = 0;   // arrived but not delivered (incomplete, or partner missing)
  std::uint64_t packets_resent = 0;     // transport retransmissions (GigE Vision), if any
  std::uint64_t pairs_delivered = 0;
  std::uint64_t pairs_discarded = 0;     // pairs not delivered because a frame was incomplete or lost
  std::uint64_t pairs_overflowed = 0;    // complete pairs dropped because next_pair() fell behind
  std::uint64_t pairs_not_read_out = 0;  // triggered but still in the camera when it was stopped
  std::uint64_t reconnects = 0;          // times the device was lost and opened again
};

// A trigger whose pair the camera did not deliver, and why (CameraCounters counts them; this says
// which trigger it was).
struct PairDrop {
  enum class Reason {
    Incomplete,     // a frame arrived with missing data
    Unpaired,       // one frame came, its partner never did (or too late)
    QueueOverflow,  // a complete pair dropped because next_pair() fell behind
    NotReadOut,     // triggered, but still inside the camera when it was stopped
  };
  std::uint64_t trigger_index = 0;
  Reason reason = Reason::Unpaired;
};
// "incomplete frame", "unpaired frame", "camera queue overflow", "not read out before stop".
const char* to_string(PairDrop::Reason reason);

// Idle → Armed → Running → (stop) → Armed. Lost while the device is gone (a backend that can
// reconnect returns to the state it had). Calls in the wrong state throw StateError.
enum class CameraState { Idle, Armed, Running, Lost };
const char* to_string(CameraState state);

struct CameraStatus {
  CameraState state = CameraState::Idle;
  bool connected = true;
  // The camera cannot go on and will not come back by itself (a backend fault, not a
  // disconnect it can recover from): a run using it fails with last_error.
  bool failed = false;
  std::string last_error;  // empty when all is well; e.g. "control lost: heartbeat timed out"
};

// A simulated camera's external trigger input: where a simulated trigger's camera line is wired
// (drivers/trigger/camera_wiring.hpp), as a cable is plugged into a real camera's trigger input.
// Real cameras have none (their input is the cable). A rising edge exposes one pair when the
// camera is running and armed for TriggerSource::External; other edges are ignored, as a real
// camera ignores its line then. Called on the trigger's thread: keep it short.
class TriggerInput {
 public:
  virtual ~TriggerInput() = default;
  virtual void rising_edge() = 0;
  // The laser fired (a Q-switch), at `time_ns` on the trigger's clock. A real camera does not see
  // it; a simulated one uses it to move its scene by the time between an exposure's two pulses.
  virtual void laser_pulse(std::uint64_t /*time_ns*/) {}
};

class FramePool;

// Thread safety: one thread controls a camera (configure/arm/start/stop/software_trigger);
// next_pair() may be called from another thread; counters() and status() from any thread.
class Camera {
 public:
  virtual ~Camera() = default;

  virtual CameraInfo info() const = 0;
  // Allowed in Idle and Armed. Bad values (ROI outside the sensor, format the device lacks) are an
  // InputError naming the setting.
  virtual void configure(const CameraSettings& settings) = 0;
  // Sets the device up for two frames per trigger. Allowed in Idle and Armed; leads to Armed.
  virtual void arm(const DoubleExposureSettings& settings) = 0;
  virtual void start() = 0;  // Armed → Running
  // Running → Armed; a no-op in other states, so it is always safe. Exposures already triggered are
  // delivered within a bound (a second or two); what the camera has not read out by then is
  // dropped (PairDrop::NotReadOut), so that stopping never waits without end.
  virtual void stop() = 0;
  // Fires one pair (TriggerSource::Software only).
  virtual void software_trigger() = 0;
  // Waits up to `timeout` for the next complete pair. nullopt on timeout, or at once when not
  // running and nothing is queued. Pairs already queued when stop() was called are still returned.
  virtual std::optional<FramePair> next_pair(std::chrono::milliseconds timeout) = 0;

  virtual CameraCounters counters() const = 0;
  virtual CameraStatus status() const = 0;
  // The pairs dropped since the last call, oldest first (bounded: when nobody takes them, the
  // oldest are forgotten; the counters keep counting).
  virtual std::vector<PairDrop> take_drops() { return {}; }
  // The simulated trigger input, or null for a camera triggered through a cable (or by software).
  virtual TriggerInput* trigger_input() { return nullptr; }
  // Where this camera's frame buffers come from, or null: a consumer gives a delivered pair's
  // buffers back there (share_pair in frame_pool.hpp) so that the next frames reuse them.
  virtual std::shared_ptr<FramePool> frame_pool() { return nullptr; }
};

}  // namespace plenopiv::drivers
