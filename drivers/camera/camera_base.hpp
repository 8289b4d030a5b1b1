// What every camera backend shares: the state machine, pairing, the pair queue and the counters.
#pragma once

#include <condition_variable>
#include <deque>
#include <memory>
#include <mutex>
#include <optional>
#include <string>

#include "drivers/camera/camera.hpp"
#include "drivers/camera/frame_pairer.hpp"
#include "drivers/camera/frame_pool.hpp"

namespace plenopiv::drivers {

// A backend implements the do_* hooks (called with the state already checked, from the control
// caller's thread) and hands every frame it receives to submit_frame(), from any one thread.
class CameraBase : public Camera {
 public:
  CameraInfo info() const override;
  void configure(const CameraSettings& settings) override;
  void arm(const DoubleExposureSettings& settings) override;
  void start() override;
  void stop() override;
  void software_trigger() override;
  std::optional<FramePair> next_pair(std::chrono::milliseconds timeout) override;
  CameraCounters counters() const override;
  CameraStatus status() const override;
  std::vector<PairDrop> take_drops() override;
  std::shared_ptr<FramePool> frame_pool() override { return pool_; }

 protected:
  explicit CameraBase(CameraInfo info, PairerOptions pairing = {}, std::size_t queue_capacity = 16);

  virtual void do_configure(const CameraSettings& settings) = 0;
  virtual void do_arm(const DoubleExposureSettings& settings) = 0;
  virtual void do_start() = 0;
  virtual void do_stop() = 0;
  virtual void do_software_trigger() = 0;
  virtual std::uint64_t packets_resent() const { return 0; }

  // Where the backend takes its frames' pixels (frame_pool.hpp).
  FramePool& frame_buffers() { return *pool_; }
  // Now on the clock of Frame::host_timestamp_ns (CLOCK_REALTIME), which the pairer's wait for a
  // frame B is timed against: a backend stamps its frames' arrival with it.
  static std::uint64_t host_now_ns();
  // Thread-safe; frames from one backend thread, in arrival order.
  void submit_frame(Frame frame, std::optional<std::uint64_t> trigger_index = {});
  // Triggers the backend dropped itself (e.g. not read out before stop), counted and listed.
  void report_dropped(std::uint64_t trigger_index, PairDrop::Reason reason);
  // The device went away: status shows Lost and `reason` until report_reconnected().
  void report_lost(const std::string& reason);
  // The backend cannot go on (a fault it will not recover from): status shows Lost, failed and
  // `reason`, for good.
  void report_failed(const std::string& reason);
  // The device is back with its configuration re-applied; frame ids start afresh.
  void report_reconnected();
  void set_pairing(const PairerOptions& options);
  void set_info(const CameraInfo& info);
  // The state the user asked for (for a backend that restores it after a reconnect).
  CameraState wanted_state() const;

 private:
  void require(std::initializer_list<CameraState> allowed, const char* call) const;

  mutable std::mutex mutex_;
  std::condition_variable ready_;
  CameraInfo info_;
  CameraState state_ = CameraState::Idle;  // wanted state; status() shows Lost while lost
  bool lost_ = false;
  bool failed_ = false;
  std::string last_error_;
  FramePairer pairer_;
  std::deque<FramePair> queue_;
  std::size_t capacity_;
  std::uint64_t overflowed_ = 0;
  std::uint64_t not_read_out_ = 0;
  std::deque<PairDrop> drops_;  // from the pairer, the queue and the backend, oldest first
  std::uint64_t reconnects_ = 0;
  const std::shared_ptr<FramePool> pool_ = std::make_shared<FramePool>();
};

}  // namespace plenopiv::drivers
