// The run state machine of plenopivd: which requests are allowed when, as pure logic.
#pragma once

#include <mutex>
#include <stdexcept>
#include <string>

namespace plenopiv::daemon {

// Idle → Armed (start accepted, devices being set up) → Acquiring (pairs arriving) → Draining
// (stop requested or pair count reached: in-flight pairs finish, the run folder is closed) → Idle.
// Any state → Error when a device or the recorder fails; Error is left by a new start, a stop
// (which acknowledges the error) or a calibration.
enum class RunState { Idle, Armed, Acquiring, Draining, Error };
const char* to_string(RunState state);

// A request that the current state does not allow. The control server answers WRONG_STATE with
// this message; nothing was changed.
class WrongStateError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// Thread safe: the control thread asks, the run thread reports progress.
class RunStateMachine {
 public:
  RunState state() const;
  std::string run_id() const;  // of the current (or last) run
  std::string error() const;   // what put it into Error

  // Operator requests: each throws WrongStateError (and changes nothing) when not allowed.
  void start(const std::string& run_id);   // Idle|Error → Armed
  void stop();                             // Armed|Acquiring → Draining; Error → Idle
  void check_calibration_allowed() const;  // Idle|Error only: calibration needs the camera
  // The run could not be set up (camera not found, folder not writable): Armed → Idle, as if the
  // start had been refused.
  void cancel_start();

  // Progress reported by the run itself. These are the run thread's own steps, so a call in
  // another state is a bug and throws std::logic_error.
  void acquiring();                   // Armed → Acquiring
  void finishing();                   // Acquiring → Draining (pair count or duration reached); no-op if Draining
  void drained();                     // Draining → Idle
  void fail(const std::string& why);  // any → Error

 private:
  [[noreturn]] void refuse(const std::string& what) const;
  mutable std::mutex mutex_;
  RunState state_ = RunState::Idle;
  std::string run_id_;
  std::string error_;
};

}  // namespace plenopiv::daemon
