// Errors drivers raise besides bad input: a device that failed, a call made in the wrong state.
#pragma once

#include <stdexcept>

namespace plenopiv::drivers {

// The device itself failed or vanished (I/O error, lost control channel, refused setting).
class DeviceError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// A call the driver's state machine does not allow now (e.g. start before arm). A bug in the
// caller, reported with the state and the call so it can be fixed.
class StateError : public std::logic_error {
 public:
  using std::logic_error::logic_error;
};

}  // namespace plenopiv::drivers
