// What every camera backend shares: the state machine, pairing, the pair queue and the counters.
#include "drivers/camera/camera_base.hpp"

#include <algorithm>
#include <string>

#include "core/base/errors.hpp"
#include "drivers/common/driver_errors.hpp"

namespace plenopiv::drivers {
std::uint64_t CameraBase::host_now_ns() {
  return std::uint64_t(
      std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::system_clock::now().time_since_epoch())
          .count());
}

const char* to_string(PixelFormat format) {
  switch (format) {
    case PixelFormat::Mono8:
      return "Mono8";
    case PixelFormat::Mono12:
      return "Mono12";
    case PixelFormat::Mono16:
      return "Mono16";
  }
  return "?";
}

PixelFormat pixel_format_from_string(const std::string& name) {
  if (name == "Mono8") return PixelFormat::Mono8;
  if (name == "Mono12") return PixelFormat::Mono12;
  if (name == "Mono16") return PixelFormat::Mono16;
  throw InputError("pixel format '" + name + "': expected Mono8, Mono12 or Mono16");
}

int bit_depth(PixelFormat format) {
  switch (format) {
    case PixelFormat::Mono8:
      return 8;
    case PixelFormat::Mono12:
      return 12;
    case PixelFormat::Mono16:
      return 16;
  }
  return 16;
}

const char* to_string(PairDrop::Reason reason) {
  switch (reason) {
    case PairDrop::Reason::Incomplete:
      return "incomplete frame";
    case PairDrop::Reason::Unpaired:
      return "unpaired frame";
    case PairDrop::Reason::QueueOverflow:
      return "camera queue overflow";
    case PairDrop::Reason::NotReadOut:
      return "not read out before stop";
  }
  return "?";
}

const char* to_string(CameraState state) {
  switch (state) {
    case CameraState::Idle:
      return "idle";
    case CameraState::Armed:
      return "armed";
    case CameraState::Running:
      return "running";
    case CameraState::Lost:
      return "lost";
  }
  return "?";
}

CameraBase::CameraBase(CameraInfo info, PairerOptions pairing, std::size_t queue_capacity)
    : info_(std::move(info)), pairer_(pairing), capacity_(std::max<std::size_t>(queue_capacity, 1)) {}

CameraInfo CameraBase::info() const {
  std::lock_guard lock(mutex_);
  return info_;
}

void CameraBase::set_info(const CameraInfo& info) {
  std::lock_guard lock(mutex_);
  info_ = info;
}

void CameraBase::require(std::initializer_list<CameraState> allowed, const char* call) const {
  std::lock_guard lock(mutex_);
  if (lost_) {
    throw DeviceError("camera " + info_.uri + ": " + call + " refused: the camera is lost (" + last_error_ + ")");
  }
  if (std::find(allowed.begin(), allowed.end(), state_) == allowed.end()) {
    throw StateError("camera " + info_.uri + ": " + call + " is not allowed while " + to_string(state_));
  }
}

void CameraBase::configure(const CameraSettings& settings) {
  require({CameraState::Idle, CameraState::Armed}, "configure");
  const CameraInfo info = this->info();
  if (!(settings.exposure_s > 0)) {
    throw InputError("camera " + info.uri + ": exposure_s must be > 0, got " + std::to_string(settings.exposure_s));
  }
  const Roi& r = settings.roi;
  if (r.x < 0 || r.y < 0 || r.width < 0 || r.height < 0 ||
      (info.sensor_width_px > 0 && r.x + r.width > info.sensor_width_px) ||
      (info.sensor_height_px > 0 && r.y + r.height > info.sensor_height_px)) {
    throw InputError("camera " + info.uri + ": roi " + std::to_string(r.x) + "," + std::to_string(r.y) + " " +
                     std::to_string(r.width) + "x" + std::to_string(r.height) + " does not fit the " +
                     std::to_string(info.sensor_width_px) + "x" + std::to_string(info.sensor_height_px) + " sensor");
  }
  do_configure(settings);
}

void CameraBase::arm(const DoubleExposureSettings& settings) {
  require({CameraState::Idle, CameraState::Armed}, "arm");
  if (!(settings.max_pair_gap_s >= 0 && settings.max_pair_gap_s <= 10)) {
    throw InputError("camera " + info().uri + ": max_pair_gap_s must be within 0..10 s");
  }
  do_arm(settings);
  std::lock_guard lock(mutex_);
  state_ = CameraState::Armed;
}

void CameraBase::start() {
  require({CameraState::Armed}, "start");
  {
    std::lock_guard lock(mutex_);
    pairer_.restart_sequence();
  }
  do_start();
  std::lock_guard lock(mutex_);
  state_ = CameraState::Running;
}

void CameraBase::stop() {
  {
    std::lock_guard lock(mutex_);
    if (state_ != CameraState::Running) return;
    // Set first, so a lost camera that comes back does not restart acquisition.
    state_ = CameraState::Armed;
    if (lost_) return;
  }
  do_stop();
  std::lock_guard lock(mutex_);
  pairer_.flush();
  ready_.notify_all();
}

void CameraBase::software_trigger() {
  require({CameraState::Running}, "software_trigger");
  do_software_trigger();
}

void CameraBase::submit_frame(Frame frame, std::optional<std::uint64_t> trigger_index) {
  std::lock_guard lock(mutex_);
  std::optional<FramePair> pair = pairer_.push(std::move(frame), trigger_index);
  if (!pair) return;
  for (const PairDrop& d : pairer_.take_drops()) drops_.push_back(d);
  if (queue_.size() >= capacity_) {
    // The consumer fell behind: keep the newest, count and list what was dropped.
    drops_.push_back({queue_.front().trigger_index, PairDrop::Reason::QueueOverflow});
    queue_.pop_front();
    ++overflowed_;
  }
  while (drops_.size() > FramePairer::kMaxDrops) drops_.pop_front();
  queue_.push_back(std::move(*pair));
  ready_.notify_one();
}

std::optional<FramePair> CameraBase::next_pair(std::chrono::milliseconds timeout) {
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  std::unique_lock lock(mutex_);
  while (queue_.empty()) {
    if (state_ != CameraState::Running) return std::nullopt;
    pairer_.expire(host_now_ns());
    const auto now = std::chrono::steady_clock::now();
    if (now >= deadline) return std::nullopt;
    // Wake now and then to give up on a frame A whose B never comes.
    ready_.wait_for(lock,
                    std::min<std::chrono::steady_clock::duration>(deadline - now, std::chrono::milliseconds(100)));
  }
  FramePair pair = std::move(queue_.front());
  queue_.pop_front();
  return pair;
}

CameraCounters CameraBase::counters() const {
  const std::uint64_t resent = packets_resent();
  std::lock_guard lock(mutex_);
  const PairerCounts& p = pairer_.counts();
  CameraCounters c;
  c.frames_received = p.frames_received;
  c.frames_incomplete = p.frames_incomplete;
  c.frames_lost = p.frames_lost;
  c.frames_discarded = p.frames_discarded;
  c.pairs_delivered = p.pairs_delivered;
  c.pairs_discarded = p.pairs_discarded;
  c.pairs_overflowed = overflowed_;
  c.pairs_not_read_out = not_read_out_;
  c.packets_resent = resent;
  c.reconnects = reconnects_;
  return c;
}

CameraStatus CameraBase::status() const {
  std::lock_guard lock(mutex_);
  return {lost_ ? CameraState::Lost : state_, !lost_, failed_, last_error_};
}

void CameraBase::report_lost(const std::string& reason) {
  std::lock_guard lock(mutex_);
  lost_ = true;
  last_error_ = reason;
  pairer_.flush();
  ready_.notify_all();
}

void CameraBase::report_dropped(std::uint64_t trigger_index, PairDrop::Reason reason) {
  std::lock_guard lock(mutex_);
  if (reason == PairDrop::Reason::NotReadOut) ++not_read_out_;
  drops_.push_back({trigger_index, reason});
  while (drops_.size() > FramePairer::kMaxDrops) drops_.pop_front();
}

std::vector<PairDrop> CameraBase::take_drops() {
  std::lock_guard lock(mutex_);
  for (const PairDrop& d : pairer_.take_drops()) drops_.push_back(d);
  std::vector<PairDrop> out(drops_.begin(), drops_.end());
  drops_.clear();
  return out;
}

void CameraBase::report_failed(const std::string& reason) {
  std::lock_guard lock(mutex_);
  lost_ = true;
  failed_ = true;
  last_error_ = reason;
  pairer_.flush();
  ready_.notify_all();
}

void CameraBase::report_reconnected() {
  std::lock_guard lock(mutex_);
  if (failed_) return;
  lost_ = false;
  ++reconnects_;
  last_error_.clear();
  pairer_.restart_sequence();
}

void CameraBase::set_pairing(const PairerOptions& options) {
  std::lock_guard lock(mutex_);
  pairer_.set_options(options);
}

CameraState CameraBase::wanted_state() const {
  std::lock_guard lock(mutex_);
  return state_;
}

}  // namespace plenopiv::drivers
