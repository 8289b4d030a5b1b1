// The run state machine of plenopivd: which requests are allowed when, as pure logic.
#include "daemon/run_state.hpp"

namespace plenopiv::daemon {

const char* to_string(RunState state) {
  switch (state) {
    case RunState::Idle:
      return "Idle";
    case RunState::Armed:
      return "Armed";
    case RunState::Acquiring:
      return "Acquiring";
    case RunState::Draining:
      return "Draining";
    case RunState::Error:
      return "Error";
  }
  return "?";
}

RunState RunStateMachine::state() const {
  std::lock_guard lock(mutex_);
  return state_;
}

std::string RunStateMachine::run_id() const {
  std::lock_guard lock(mutex_);
  return run_id_;
}

std::string RunStateMachine::error() const {
  std::lock_guard lock(mutex_);
  return error_;
}

void RunStateMachine::refuse(const std::string& what) const {
  std::string why = what + ": the daemon is " + to_string(state_);
  if (!run_id_.empty() && state_ != RunState::Idle) why += " (run " + run_id_ + ")";
  throw WrongStateError(why);
}

void RunStateMachine::start(const std::string& run_id) {
  std::lock_guard lock(mutex_);
  if (state_ != RunState::Idle && state_ != RunState::Error) {
    refuse("cannot start a run while another is in progress; stop it first (plenopiv run stop)");
  }
  state_ = RunState::Armed;
  run_id_ = run_id;
  error_.clear();
}

void RunStateMachine::stop() {
  std::lock_guard lock(mutex_);
  switch (state_) {
    case RunState::Armed:
    case RunState::Acquiring:
      state_ = RunState::Draining;
      return;
    case RunState::Error:
      state_ = RunState::Idle;
      error_.clear();
      return;
    case RunState::Idle:
      refuse("no run to stop");
    case RunState::Draining:
      refuse("the run is already stopping");
  }
}

void RunStateMachine::check_calibration_allowed() const {
  std::lock_guard lock(mutex_);
  if (state_ != RunState::Idle && state_ != RunState::Error) {
    refuse("cannot take calibration images during a run; stop it first (plenopiv run stop)");
  }
}

void RunStateMachine::cancel_start() {
  std::lock_guard lock(mutex_);
  if (state_ != RunState::Armed && state_ != RunState::Draining) {
    throw std::logic_error(std::string("run state: cancel_start() in state ") + to_string(state_));
  }
  state_ = RunState::Idle;
}

void RunStateMachine::acquiring() {
  std::lock_guard lock(mutex_);
  if (state_ == RunState::Draining) return;  // stopped while arming: the run thread drains
  if (state_ != RunState::Armed) {
    throw std::logic_error(std::string("run state: acquiring() in state ") + to_string(state_));
  }
  state_ = RunState::Acquiring;
}

void RunStateMachine::finishing() {
  std::lock_guard lock(mutex_);
  if (state_ == RunState::Draining) return;
  if (state_ != RunState::Acquiring) {
    throw std::logic_error(std::string("run state: finishing() in state ") + to_string(state_));
  }
  state_ = RunState::Draining;
}

void RunStateMachine::drained() {
  std::lock_guard lock(mutex_);
  if (state_ != RunState::Draining) {
    throw std::logic_error(std::string("run state: drained() in state ") + to_string(state_));
  }
  state_ = RunState::Idle;
}

void RunStateMachine::fail(const std::string& why) {
  std::lock_guard lock(mutex_);
  state_ = RunState::Error;
  error_ = why;
}

}  // namespace plenopiv::daemon
